"""One episode runner for every closed loop: record, evaluate, autonomous, the manual window,
DAgger.

- :mod:`clonedrive.episode.rules`: intervention, time limit and stop reasons (one definition);
- :mod:`clonedrive.episode.runner`: :class:`~clonedrive.episode.runner.Episode`,
  :class:`~clonedrive.episode.runner.Runner` (N cars in lock-step, an optional labeller), the
  driver protocols;
- :mod:`clonedrive.episode.drivers`: the expert and the network as runner drivers;
- :mod:`clonedrive.episode.trace`: what an episode measured and its figures.

It sits between the drivers and the data stage in the layers (DESIGN.md).
"""
