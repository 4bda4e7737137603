"""clonedrive: behavioural cloning of driving, end to end and headless.

Importing the package is cheap and changes nothing: the Keras backend is chosen where Keras is
first needed (:mod:`clonedrive.base.keras_backend`), and the Gymnasium environments register when
:mod:`clonedrive.envs` is imported.
"""

__version__ = "0.2.0"
