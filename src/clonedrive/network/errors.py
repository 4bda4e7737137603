"""The error a model file that cannot be used raises, at the base of :mod:`clonedrive.network`.

Every module that reads a model file (:mod:`~clonedrive.network.keras_file`,
:mod:`~clonedrive.network.model_bounds`, :mod:`~clonedrive.network.legacy_keras`,
:mod:`~clonedrive.network.model_file`) raises :class:`ModelFileError`; it lives here, importing
nothing, so that none of them needs another only for it.
"""

from __future__ import annotations


class ModelFileError(ValueError):
    """A model file that cannot be used; the message names the file."""


def one_line(error: BaseException) -> str:
    """``error``'s message on one line, cut at 300 characters (for a :class:`ModelFileError`)."""
    text = " ".join(str(error).split())
    return text if len(text) <= 300 else text[:300] + "..."
