"""Tests here import keras directly: give it the project's default backend (as
``import clonedrive`` does) before any test module loads it."""

import os

os.environ.setdefault("KERAS_BACKEND", "torch")
