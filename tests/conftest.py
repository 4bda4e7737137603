"""Shared test set-up: the project's default Keras backend before any test module imports keras."""

from clonedrive.keras_backend import choose_backend

choose_backend()
