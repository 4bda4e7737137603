"""The Udacity simulator's fixed numbers (see UDACITY.md), each defined once.

Everything that must match the Udacity simulator, its recorded data or its ``drive.py``
imports its number from here: the camera image size, the control rate, the wheel angle that
steering 1.0 means, the drive protocol's port, the JPEG quality of its frames, ``drive.py``'s
set speed and PI gains, and the side-camera steering correction users apply by default.
A bottom-layer module: it imports nothing, so every package may use it.
"""

from __future__ import annotations

#: Camera image [pixels]: rows, columns, channels (RGB), as arrays are indexed.
IMAGE_HEIGHT = 160
IMAGE_WIDTH = 320
IMAGE_CHANNELS = 3
IMAGE_SHAPE = (IMAGE_HEIGHT, IMAGE_WIDTH, IMAGE_CHANNELS)

#: Control (and recording) rate [Hz]: one driving_log row / one telemetry per 1/15 s.
CONTROL_HZ = 15.0

#: Wheel angle [deg] at steering +-1.0; steering is applied at once (no rate limit).
MAX_WHEEL_ANGLE_DEG = 25.0

#: TCP port of the drive protocol (the simulator connects to 127.0.0.1 on it, fixed).
PORT = 4567

#: JPEG quality of recorded and streamed frames (Unity's Texture2D.EncodeToJPG default).
JPEG_QUALITY = 75

#: drive.py's set speed [mph] and the gains of its PI throttle controller
#: ``throttle = KP * e + KI * sum(e)`` with ``e = set speed - speed`` [mph].
SET_SPEED_MPH = 9.0
SPEED_KP = 0.1
SPEED_KI = 0.002

#: Added to the left camera's steering label, subtracted from the right's (the common default).
STEERING_CORRECTION = 0.2
