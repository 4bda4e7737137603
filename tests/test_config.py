import os
import stat
from dataclasses import dataclass

import pytest

from clonedrive.base.config import (
    atomic_path,
    config_from_dict,
    write_bytes_atomic,
    write_json_atomic,
    write_text_atomic,
)


@dataclass(frozen=True)
class Example:
    speed_mph: float = 15.0
    laps: int = 1


def test_unknown_keys_are_rejected_by_name():
    assert config_from_dict(Example, {"laps": 3}) == Example(laps=3)
    with pytest.raises(ValueError, match="unknown key\\(s\\) lapz"):
        config_from_dict(Example, {"lapz": 3}, source="run.json")


def test_atomic_writers_leave_whole_files_with_normal_permissions(tmp_path):
    umask = os.umask(0o022)
    try:
        paths = [write_text_atomic(tmp_path / "a.txt", "text"),
                 write_bytes_atomic(tmp_path / "b.bin", b"bytes"),
                 write_json_atomic(tmp_path / "sub" / "c.json", {"k": 1})]
    finally:
        os.umask(umask)
    assert paths[0].read_text() == "text" and paths[1].read_bytes() == b"bytes"
    assert paths[2].read_text() == '{\n  "k": 1\n}\n'
    for path in paths:
        assert stat.S_IMODE(path.stat().st_mode) == 0o644


def test_a_failed_write_leaves_neither_file_nor_temporary(tmp_path):
    (tmp_path / "keep.png").write_bytes(b"old")
    with pytest.raises(RuntimeError), atomic_path(tmp_path / "keep.png") as temporary:
        assert temporary.suffix == ".png" and temporary.parent == tmp_path
        temporary.write_bytes(b"half")
        raise RuntimeError("writer failed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.png"]
    assert (tmp_path / "keep.png").read_bytes() == b"old"
