"""The floor every other package stands on: the Udacity simulator's numbers
(``udacity_spec``), the one image decoder (``images``), config files with bounded reading and
atomic writing (``config``), safe output paths and files (``paths``, ``output_files``),
progress bars, the Keras backend, the worker pool and SIGTERM handling (``interrupts``)."""
