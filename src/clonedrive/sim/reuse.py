"""What a process builds once and reuses: the scenery and texture images of a track.

Both are pure functions of the track's geometry, the look's style and the road wear, and cost
0.2-0.3 s a scene (lake: 0.16 s of scenery, 0.08 s of textures). A process that drives several
cars on one track, together (a lock-step group of set speeds: 8 cars build one scenery) or one
after the other (a notebook, the tests), builds them once. (Pool workers are fresh processes
for each task: see :mod:`clonedrive.base.workers`.) What it hands out is shared, so it is only read.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import TypeVar

from clonedrive.world.track import Track

T = TypeVar("T")

#: How many built things a process keeps, the least recently used going first. A track's scene
#: keeps about a dozen (its scenery, its textures, its meshes cut into cells per material), so
#: this is two or three tracks (about 8 MB each).
KEEP = 32

_kept: OrderedDict[Hashable, object] = OrderedDict()


def track_key(track: Track) -> tuple[str, str, str]:
    """A key that is equal for tracks with the same name, theme and geometry."""
    digest = hashlib.blake2b(digest_size=16)
    for table in (track.xyz, track.width):
        digest.update(table.tobytes())
    return track.name, track.theme, digest.hexdigest()


def reused(key: Hashable, build: Callable[[], T]) -> T:
    """``build()``'s result for ``key``: built on the first call, then the same object."""
    if key in _kept:
        _kept.move_to_end(key)
        return _kept[key]  # type: ignore[return-value]
    value = build()
    _kept[key] = value
    while len(_kept) > KEEP:
        _kept.popitem(last=False)
    return value


def forget() -> None:
    """Drop everything kept (tests; a process that is done with its tracks)."""
    _kept.clear()
