"""``clonedrive web``: the manual session (:mod:`clonedrive.manual.session`) driven and watched
from a browser page, with the expert or a model as pilots and HG-DAgger takeovers."""
