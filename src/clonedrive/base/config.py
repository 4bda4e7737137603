"""Stage configuration: frozen dataclasses, unknown keys rejected, saved as ``config.json``.

Each stage defines its own frozen dataclass next to the code that uses it (defaults are defined
once, there); this module holds the shared loading/saving rules.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import sys
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from clonedrive.base.output_files import clear_temporary, open_output

T = TypeVar("T")

#: Largest JSON file :func:`read_json` reads unless the caller sets its own limit [bytes].
MAX_JSON_BYTES = 16 << 20
#: Deepest nesting of arrays and objects :func:`read_json` accepts.
MAX_JSON_DEPTH = 32
#: Longest number literal :func:`read_json` accepts [characters]; a double has 17 digits.
MAX_JSON_NUMBER_CHARS = 40
_BYTE_ORDER_MARKS = (
    (b"\xff\xfe\x00\x00", "UTF-32"), (b"\x00\x00\xfe\xff", "UTF-32"),
    (b"\xff\xfe", "UTF-16"), (b"\xfe\xff", "UTF-16"),
)


class JsonFileError(ValueError):
    """A JSON file that cannot be read; the message names the file and the problem."""


def config_from_dict(cls: type[T], values: dict[str, Any], *, source: str = "config") -> T:
    """Build ``cls`` from ``values``; unknown keys, and values ``cls`` refuses, raise
    ``ValueError`` naming ``source``."""
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    known = {field.name for field in dataclasses.fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(
            f"{source}: unknown key(s) {', '.join(unknown)} for {cls.__name__}; "
            f"expected some of: {', '.join(sorted(known))}"
        )
    try:
        return cls(**values)
    except (TypeError, ValueError) as error:  # __post_init__'s checks (a str where a number...)
        raise ValueError(f"{source}: {error}") from None


def check_field_types(config: Any) -> None:
    """``ValueError`` naming the first field of the dataclass ``config`` whose value is not of
    its annotated type: ``int`` (not a bool), ``float`` (an int is one; not a bool), ``bool``,
    ``str``, or one of those ``| None``. Other annotations are not checked. A recipe's
    ``epochs = 2.5`` or ``batch_size = true`` is refused here, before any data is read."""
    import types
    import typing

    hints = typing.get_type_hints(type(config))
    for field in dataclasses.fields(config):
        expected = hints.get(field.name)
        value = getattr(config, field.name)
        allowed = (typing.get_args(expected)
                   if isinstance(expected, types.UnionType) else (expected,))
        if not all(kind in _CHECKED or kind is type(None) for kind in allowed):
            continue
        if not any(_is_a(value, kind) for kind in allowed):
            names = " or ".join(_CHECKED.get(kind, "None") for kind in allowed)
            raise ValueError(f"{field.name} must be {names}, got {value!r}")


#: The annotations :func:`check_field_types` checks, and how its message names each.
_CHECKED = {int: "a whole number", float: "a number", bool: "true or false", str: "text"}


def _is_a(value: Any, kind: type) -> bool:
    """``value`` is of ``kind`` (NumPy's numbers count as Python's)."""
    import numbers

    if kind is type(None):
        return value is None
    if isinstance(value, bool):
        return kind is bool
    if kind is int:
        return isinstance(value, numbers.Integral)
    if kind is float:
        return isinstance(value, numbers.Real)
    return isinstance(value, kind)


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
        yield clear_temporary(temporary)  # a link planted at that name is removed, not followed
        os.replace(temporary, path)
    except OSError as error:
        temporary.unlink(missing_ok=True)
        # A failed write or fsync does not say which file (ENOSPC: "No space left on device").
        if error.filename is None and error.errno is not None:
            raise OSError(error.errno, error.strerror, str(path)) from error
        raise
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` via :func:`atomic_path` (no fsync: a crash of the process
    cannot lose it, only a power loss can)."""
    with atomic_path(path) as temporary:
        with open_output(temporary, "wb") as handle:
            handle.write(data)
    return Path(path)


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` via :func:`atomic_path`, fsynced before the rename."""
    with atomic_path(path) as temporary, open_output(temporary, "w") as handle:
        handle.write(text)
        handle.flush()
        os.fsync(handle.fileno())
    return Path(path)


def write_json_atomic(path: str | os.PathLike, data: Any) -> Path:
    """Write ``data`` as indented JSON, atomically and fsynced (:func:`write_text_atomic`)."""
    return write_text_atomic(path, json.dumps(data, indent=2, sort_keys=False) + "\n")


def parse_toml(text: str, *, source: str) -> dict[str, Any]:
    """The TOML document ``text``, or ``ValueError`` naming ``source``: for text that is not
    TOML, for arrays or inline tables nested so deep (100 KB of ``[[[[``) that Python's
    parser, which recurses once per level, runs out of stack, and for an integer outside
    :data:`TOML_INTEGER_RANGE` (which every float check would meet as an OverflowError)."""
    import tomllib

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"{source}: not valid TOML: {error}") from None
    except RecursionError:
        raise ValueError(f"{source}: arrays or tables nested too deep to read (more than "
                         f"about {sys.getrecursionlimit()} levels)") from None
    except ValueError:  # int() of more digits than Python converts (sys.get_int_max_str_digits)
        raise ValueError(f"{source}: an integer with too many digits; TOML integers are 64-bit "
                         f"({TOML_INTEGER_RANGE[0]} to {TOML_INTEGER_RANGE[1]})") from None
    _check_integers(data, source)
    return data


#: TOML's integers are 64-bit signed ("if an integer cannot be represented losslessly, an
#: error must be thrown", toml.io v1.0.0); Python's parser reads integers of any size.
TOML_INTEGER_RANGE = (-(2**63), 2**63 - 1)


def _check_integers(data: dict[str, Any], source: str) -> None:
    """``ValueError`` naming the key of the first integer outside TOML's 64 bits (walked
    without recursion: the document may be nested hundreds of levels deep)."""
    low, high = TOML_INTEGER_RANGE
    pending: list[tuple[str, Any]] = [("", data)]
    while pending:
        where, value = pending.pop()
        if isinstance(value, dict):
            pending += [(f"{where}.{key}" if where else str(key), item)
                        for key, item in value.items()]
        elif isinstance(value, list):
            pending += [(f"{where}[{index}]", item) for index, item in enumerate(value)]
        elif isinstance(value, int) and not isinstance(value, bool) \
                and not low <= value <= high:
            raise ValueError(f"{source}: {where} is an integer of {len(str(abs(value)))} "
                             f"digits; TOML integers are 64-bit ({low} to {high})")


def changed_settings(saved: Any, wanted: dict[str, Any], *,
                     may_change: Iterable[str] = ()) -> list[str]:
    """Each setting a run folder's saved settings (``saved``, its config.json) hold with
    another value than ``wanted`` (both JSON-ready dicts, :func:`config_to_dict`), as
    ``"key OLD -> NEW"``; keys in ``may_change``, and keys only one side has (a folder written
    by an older version), are not compared. A run that reuses a folder's results must not
    label them with settings they were not made with."""
    if not isinstance(saved, dict):
        return ["config.json is not a JSON object"]
    skip = set(may_change)
    return [f"{key} {saved[key]!r} -> {wanted[key]!r}" for key in wanted
            if key in saved and key not in skip and saved[key] != wanted[key]]


def save_config(config: Any, path: str | os.PathLike, **extra: Any) -> Path:
    """Save a config dataclass (plus ``extra`` top-level entries) as JSON, atomically."""
    data = config_to_dict(config)
    data.update(extra)
    return write_json_atomic(path, data)


def load_config(cls: type[T], path: str | os.PathLike) -> T:
    """Load a config dataclass saved by :func:`save_config` (extra top-level keys ignored
    only if they were saved as extras is not supported: every key must be a field)."""
    values = read_json(path, what="config file")
    if not isinstance(values, dict):
        raise ValueError(f"{path}: expected a JSON object")
    return config_from_dict(cls, values, source=str(path))


def read_json(path: str | os.PathLike, *, max_bytes: int = MAX_JSON_BYTES,
              what: str = "JSON file") -> Any:
    """The value in the UTF-8 JSON file ``path``, read with bounded memory and time.

    Refused with one :class:`JsonFileError` line naming ``path`` (``what`` says what the file
    should have been): a folder, a file over ``max_bytes`` (checked before reading it), UTF-16
    or UTF-32 text, binary data, text that is not UTF-8, nesting deeper than
    :data:`MAX_JSON_DEPTH`, a number longer than :data:`MAX_JSON_NUMBER_CHARS` characters,
    ``NaN``/``Infinity``, or invalid JSON. A missing file raises ``FileNotFoundError``.
    """
    path = Path(path)
    if path.is_dir():
        raise JsonFileError(f"{path}: is a folder; expected a {what}")
    if path.exists() and not path.is_file():
        raise JsonFileError(f"{path}: is not a regular file; expected a {what}")
    try:
        with open(path, "rb") as handle:
            data = handle.read(max_bytes + 1)
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such {what}") from None
    if len(data) > max_bytes:
        raise JsonFileError(
            f"{path}: larger than the {_size_text(max_bytes)} a {what} may be; not a {what}?")
    for mark, encoding in _BYTE_ORDER_MARKS:
        if data.startswith(mark):
            raise JsonFileError(f"{path}: {encoding} text (byte-order mark); save it as UTF-8")
    if b"\x00" in data[:4096]:
        wide = data[:2].count(b"\x00") == 1 and data[:4096].count(b"\x00") * 3 > len(data[:4096])
        detail = "UTF-16 text without a byte-order mark; save it as UTF-8" if wide else \
            f"binary data (NUL bytes), not a {what}"
        raise JsonFileError(f"{path}: {detail}")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise JsonFileError(
            f"{path}: not UTF-8 text (bad byte at offset {error.start}); not a {what}?") from None

    def number(kind: type) -> Any:
        def parse(literal: str) -> Any:
            if len(literal) > MAX_JSON_NUMBER_CHARS:
                raise JsonFileError(
                    f"{path}: a number of {len(literal)} characters ({literal[:12]}...); "
                    f"at most {MAX_JSON_NUMBER_CHARS} are accepted")
            value = kind(literal)
            if kind is float and not math.isfinite(value):  # 1e999 reads as infinity
                raise JsonFileError(f"{path}: the number {literal[:24]} is too large for a "
                                    "float; use a finite number")
            return value
        return parse

    def constant(name: str) -> Any:
        raise JsonFileError(f"{path}: {name} is not a JSON number; use a finite number")

    try:
        value = json.loads(text, parse_int=number(int), parse_float=number(float),
                           parse_constant=constant)
    except json.JSONDecodeError as error:
        raise JsonFileError(f"{path}: not valid JSON ({error})") from None
    except RecursionError:  # the C decoder stops at the interpreter's recursion limit
        value, depth = None, sys.getrecursionlimit()
    else:
        depth = _json_depth(value)
    if depth > MAX_JSON_DEPTH:
        raise JsonFileError(
            f"{path}: nested {'more than ' if value is None else ''}{depth} levels deep; "
            f"a {what} is nested at most {MAX_JSON_DEPTH} levels")
    return value


def _json_depth(value: Any) -> int:
    """Deepest nesting of lists and dicts in a decoded JSON value (iterative, no recursion)."""
    deepest = 0
    pending = [(value, 1)] if isinstance(value, (list, dict)) else []
    while pending:
        item, depth = pending.pop()
        deepest = max(deepest, depth)
        children = item.values() if isinstance(item, dict) else item
        pending.extend((child, depth + 1) for child in children
                       if isinstance(child, (list, dict)))
    return deepest


def _size_text(count: int) -> str:
    return f"{count / (1 << 20):g} MiB" if count >= 1 << 20 else f"{count / 1024:g} KiB"
