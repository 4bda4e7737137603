"""Stage configuration: frozen dataclasses, unknown keys rejected, saved as ``config.json``.

Each stage defines its own frozen dataclass next to the code that uses it (defaults are defined
once, there); this module holds the shared loading/saving rules.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")


def config_from_dict(cls: type[T], values: dict[str, Any], *, source: str = "config") -> T:
    """Build ``cls`` from ``values``; unknown keys raise ``ValueError`` naming them."""
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    known = {field.name for field in dataclasses.fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(
            f"{source}: unknown key(s) {', '.join(unknown)} for {cls.__name__}; "
            f"expected some of: {', '.join(sorted(known))}"
        )
    return cls(**values)


def config_to_dict(config: Any) -> dict[str, Any]:
    """A JSON-ready dict of a (possibly nested) config dataclass; tuples become lists."""
    return json.loads(json.dumps(dataclasses.asdict(config), default=str))


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Write a file so that readers never see half of it.

    Yields a temporary path beside ``path`` (same suffix, so writers that choose a format by
    the name, like ``savefig`` or ``model.save``, still work); when the block succeeds the
    temporary file is renamed over ``path``, when it fails the temporary file is removed.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # The writer creates the file, so it gets the usual permissions (umask), not mkstemp's 0600.
    temporary = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    try:
        yield temporary
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` via :func:`atomic_path` (no fsync: a crash of the process
    cannot lose it, only a power loss can)."""
    with atomic_path(path) as temporary:
        temporary.write_bytes(data)
    return Path(path)


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` via :func:`atomic_path`, fsynced before the rename."""
    with atomic_path(path) as temporary, open(temporary, "w", encoding="utf-8") as handle:
        handle.write(text)
        handle.flush()
        os.fsync(handle.fileno())
    return Path(path)


def write_json_atomic(path: str | os.PathLike, data: Any) -> Path:
    """Write ``data`` as indented JSON, atomically and fsynced (:func:`write_text_atomic`)."""
    return write_text_atomic(path, json.dumps(data, indent=2, sort_keys=False) + "\n")


def save_config(config: Any, path: str | os.PathLike, **extra: Any) -> Path:
    """Save a config dataclass (plus ``extra`` top-level entries) as JSON, atomically."""
    data = config_to_dict(config)
    data.update(extra)
    return write_json_atomic(path, data)


def load_config(cls: type[T], path: str | os.PathLike) -> T:
    """Load a config dataclass saved by :func:`save_config` (extra top-level keys ignored
    only if they were saved as extras is not supported: every key must be a field)."""
    with open(path, encoding="utf-8") as handle:
        values = json.load(handle)
    if not isinstance(values, dict):
        raise ValueError(f"{path}: expected a JSON object")
    return config_from_dict(cls, values, source=str(path))
