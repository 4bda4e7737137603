"""A drive server written the way Udacity's ``drive.py`` is, for tests of our simulator's client.

Usage: ``python udacity_style_server.py MODEL.h5 [PORT]`` (PORT 0 picks a free one). It uses the
stack the Udacity starter kit works with -- python-socketio 4.x on python-engineio 3.13.x, a
Flask app wrapped by ``socketio.Middleware``, served by ``eventlet.wsgi`` -- and behaves as
drive.py does: on ``connect`` it sends ``steer`` 0/0; on ``telemetry`` it decodes the base64 JPEG
with PIL (RGB), predicts the steering with ``model.predict(image[None], batch_size=1)``, computes
the throttle with a PI controller (kp 0.1, ki 0.002, set speed 9 mph) and emits ``steer`` with
the values as ``str(float)``; on ``telemetry`` with no data (manual mode) it emits ``manual``.

Unlike drive.py it listens on 127.0.0.1 only, and prints ``listening on 127.0.0.1:<port>`` once
the socket is bound, so a test can start it on port 0. Run it in its own process: eventlet
monkey-patches the interpreter.
"""

from __future__ import annotations

import base64
import sys
from io import BytesIO

import eventlet
import eventlet.wsgi
import keras
import numpy as np
import socketio
from flask import Flask
from PIL import Image

sio = socketio.Server()
flask_app = Flask(__name__)
steering_model = None


class ProportionalIntegral:
    """throttle = kp * error + ki * (sum of errors), error = set speed - speed (mph)."""

    def __init__(self, kp: float, ki: float) -> None:
        self.kp = kp
        self.ki = ki
        self.target_mph = 0.0
        self.error_sum = 0.0

    def set_target(self, target_mph: float) -> None:
        self.target_mph = target_mph

    def update(self, speed_mph: float) -> float:
        error = self.target_mph - speed_mph
        self.error_sum += error
        return self.kp * error + self.ki * self.error_sum


speed_control = ProportionalIntegral(0.1, 0.002)
speed_control.set_target(9.0)


def send_steer(steering_angle: float, throttle: float) -> None:
    sio.emit(
        "steer",
        data={"steering_angle": str(steering_angle), "throttle": str(throttle)},
        skip_sid=True,
    )


@sio.on("telemetry")
def on_telemetry(sid, data):
    if not data:
        # The simulator is driven by hand: keep its loop alive.
        sio.emit("manual", data={}, skip_sid=True)
        return
    speed_mph = float(data["speed"])
    picture = Image.open(BytesIO(base64.b64decode(data["image"])))
    pixels = np.asarray(picture)
    prediction = steering_model.predict(pixels[None, :, :, :], batch_size=1, verbose=0)
    steering_angle = float(prediction[0][0])
    throttle = speed_control.update(speed_mph)
    print(f"steer {steering_angle} throttle {throttle}", flush=True)
    send_steer(steering_angle, throttle)


@sio.on("connect")
def on_connect(sid, environ):
    print(f"connect {sid}", flush=True)
    send_steer(0, 0)


def main(argv: list[str]) -> int:
    global steering_model
    if len(argv) not in (1, 2):
        print("usage: udacity_style_server.py MODEL.h5 [PORT]", file=sys.stderr)
        return 2
    steering_model = keras.models.load_model(argv[0], compile=False)
    port = int(argv[1]) if len(argv) == 2 else 4567
    app = socketio.Middleware(sio, flask_app)
    listener = eventlet.listen(("127.0.0.1", port))
    print(f"listening on 127.0.0.1:{listener.getsockname()[1]}", flush=True)
    eventlet.wsgi.server(listener, app)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
