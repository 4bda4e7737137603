"""Closed-loop replay of a model through a real Udacity log by viewpoint synthesis.

:mod:`clonedrive.replay.view` moves the recorded camera sideways and turns it (a flat-road
homography below the horizon, a pure rotation above); :mod:`clonedrive.replay.episode` drives
the car's offset from the recorded path with the model's steering; :mod:`clonedrive.replay.output`
writes ``replay.json``, ``replay.png`` and the optional video.
"""
