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


@pytest.mark.parametrize("literal", ["1e999", "-1e999", "1E400"])
def test_a_number_too_large_for_a_float_is_refused_not_read_as_infinity(tmp_path, literal):
    from clonedrive.base.config import JsonFileError, read_json

    path = tmp_path / "bench.json"
    path.write_text(f'{{"value": [1.5, {literal}]}}', encoding="utf-8")
    with pytest.raises(JsonFileError, match=f"the number {literal} is too large for a float"):
        read_json(path)
    path.write_text('{"value": [1.5, 1e300]}', encoding="utf-8")
    assert read_json(path) == {"value": [1.5, 1e300]}


@pytest.mark.parametrize(("setting", "said"), [
    ("epochs = 2.5", "[train]: epochs must be a whole number, got 2.5"),
    ("epochs = true", "[train]: epochs must be a whole number, got True"),
    ("batch_size = 64.5", "[train]: batch_size must be a whole number, got 64.5"),
    ("seed = 0.5", "[train]: seed must be a whole number, got 0.5"),
    ("seed = -1", "[train]: seed must be at least 0, got -1"),
    ("balance = 1", "[train]: balance must be true or false, got 1"),
    ("consistency = true", "[train]: consistency must be a number, got True"),
])
def test_a_recipe_s_training_values_of_the_wrong_type_are_refused_by_file_and_key(
        tmp_path, setting, said):
    from clonedrive.recipes.book import load_recipe_file
    from clonedrive.recipes.training import train_stages

    recipe = tmp_path / "r.toml"
    recipe.write_text('[recipe]\nname = "x"\nversion = 1\n[[recording]]\nname = "middle"\n'
                      'track = "lake"\nstyle = "center"\nlaps = 1\nspeed_mph = 20\n'
                      f'[train]\n{setting}\n', encoding="utf-8")
    with pytest.raises(ValueError) as refused:
        train_stages(load_recipe_file(str(recipe)))
    assert str(refused.value) == f"{recipe}: {said}"


def test_numbers_of_numpy_pass_the_type_check():
    import numpy as np

    from clonedrive.model.train_config import TrainConfig

    config = TrainConfig(epochs=np.int64(3), learning_rate=np.float32(1e-3), seed=np.int64(2))
    assert config.epochs == 3
