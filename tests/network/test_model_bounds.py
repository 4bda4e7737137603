"""Model files that would fill the memory are refused before Keras allocates anything: a
configuration declaring a huge layer, an archive member or HDF5 dataset that inflates."""

from __future__ import annotations

import resource
import shutil
from pathlib import Path

import h5py
import pytest
from support.hostile_files import (
    h5_with_huge_dense,
    keras_with_huge_dense,
    keras_with_inflating_weights,
    keras_with_input_shape,
)
from support.measured import run_measured
from support.student_models import student_model, write_keras2_h5

from clonedrive.network.model_bounds import (
    MAX_PACKING_RATIO,
    MAX_SAMPLE_VALUES,
    MAX_UNPACKED_BYTES,
    ModelBoundsError,
)
from clonedrive.network.model_file import read_model

#: A Dense layer of this many outputs on the tiny model's 8 features: 5.1 GB of weights.
HUGE_UNITS = 160_000_000
#: Peak memory a refused model file may cost a whole clonedrive process [MB].
REFUSAL_PEAK_MB = 2000


def test_a_config_declaring_a_huge_layer_is_refused_by_a_real_process(
        tiny_model_path: Path, tmp_path: Path) -> None:
    huge = keras_with_huge_dense(tiny_model_path, tmp_path / "huge.keras", HUGE_UNITS)
    assert huge.stat().st_size < 64 << 10
    out = tmp_path / "huge.onnx"
    finished = run_measured("export", huge, "--onnx", "--out", out)
    assert finished.rc == 1
    assert "Traceback" not in finished.stderr
    last = finished.stderr.strip().splitlines()[-1]
    assert last.startswith(f"clonedrive export: {huge}: its layer configuration declares 5.")
    assert "GiB of weights but the file stores" in last and "limit 1.0 GiB" in last
    assert finished.peak_rss_mb < REFUSAL_PEAK_MB
    assert not out.exists()


def test_evaluate_refuses_it_too(tiny_model_path: Path, tmp_path: Path) -> None:
    """evaluate reads the model before Keras is imported for anything else."""
    huge = keras_with_huge_dense(tiny_model_path, tmp_path / "huge.keras", HUGE_UNITS)
    finished = run_measured("evaluate", huge, "--laps", "1", "--workers", "1", "--out",
                            tmp_path / "eval")
    assert finished.rc == 2  # evaluate's status for a model it cannot use
    assert "Traceback" not in finished.stderr
    assert finished.stderr.strip().splitlines()[-1].startswith(
        f"clonedrive evaluate: {huge}: its layer configuration declares 5.")
    assert finished.peak_rss_mb < REFUSAL_PEAK_MB


def test_the_refused_network_is_never_allocated_later(tiny_model_path: Path,
                                                       tmp_path: Path) -> None:
    """Keras initialises deferred variables when a later stateless scope closes: the refused
    network's must not be among them."""
    import keras

    huge = keras_with_huge_dense(tiny_model_path, tmp_path / "huge.keras", HUGE_UNITS)
    with pytest.raises(ModelBoundsError, match="declares"):
        read_model(huge)
    before_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with keras.StatelessScope():
        pass
    grown_mib = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before_kib) / 1024
    assert grown_mib < 1024
    assert read_model(tiny_model_path).count_params() > 0


def test_a_weights_member_packed_past_the_ratio_is_refused(tiny_model_path: Path,
                                                           tmp_path: Path) -> None:
    bomb = keras_with_inflating_weights(tiny_model_path, tmp_path / "bomb.keras", 64 << 20)
    assert bomb.stat().st_size < 1 << 20
    with pytest.raises(ModelBoundsError) as refused:
        read_model(bomb)
    assert str(refused.value).startswith(f"{bomb}: model.weights.h5: 64.0 MiB unpacked from ")
    assert f"more than {MAX_PACKING_RATIO} to 1" in str(refused.value)


@pytest.mark.slow
def test_an_archive_unpacking_past_the_limit_is_refused_by_a_real_process(
        tiny_model_path: Path, tmp_path: Path) -> None:
    bomb = keras_with_inflating_weights(tiny_model_path, tmp_path / "bomb.keras",
                                        MAX_UNPACKED_BYTES + (1 << 20))
    finished = run_measured("export", bomb, "--onnx", "--out", tmp_path / "bomb.onnx")
    assert finished.rc == 1
    assert "Traceback" not in finished.stderr
    assert finished.stderr.strip().splitlines()[-1] == (
        f"clonedrive export: {bomb}: its members unpack to 1.0 GiB, over the 1.0 GiB limit "
        "for a model file; not loaded")
    assert finished.peak_rss_mb < REFUSAL_PEAK_MB


def test_a_compressed_hdf5_dataset_that_inflates_is_refused(tiny_h5_path: Path,
                                                            tmp_path: Path) -> None:
    """An HDF5 dataset never written is all fill value: 128 MiB declared, nothing stored."""
    path = tmp_path / "model.h5"
    shutil.copy(tiny_h5_path, path)
    with h5py.File(path, "a") as handle:
        handle.create_dataset("padding", shape=(32 << 20,), dtype="float32",
                              compression="gzip", chunks=(1 << 20,))
    with pytest.raises(ModelBoundsError) as refused:
        read_model(path)
    assert str(refused.value).startswith(f"{path}: its weights: 128.0 MiB unpacked from ")
    assert f"more than {MAX_PACKING_RATIO} to 1" in str(refused.value)


def test_an_h5_config_declaring_a_huge_layer_is_refused(tiny_h5_path: Path,
                                                       tmp_path: Path) -> None:
    huge = h5_with_huge_dense(tiny_h5_path, tmp_path / "huge.h5", HUGE_UNITS)
    with pytest.raises(ModelBoundsError, match=r"its layer configuration declares 5\.\d GiB"):
        read_model(huge)


def test_a_keras2_student_h5_declaring_a_huge_layer_is_refused(tmp_path: Path) -> None:
    """Keras 1/2 files are rebuilt from their layer list: that build is counted too."""
    student = write_keras2_h5(tmp_path / "student.h5", student_model(seed=0))
    huge = h5_with_huge_dense(student, tmp_path / "huge.h5", HUGE_UNITS)
    with pytest.raises(ModelBoundsError, match=r"its layer configuration declares 6\.\d GiB"):
        read_model(huge, trust=True)
    assert read_model(student, trust=True).count_params() > 0


def test_a_huge_declared_input_is_refused_before_anything_is_built(
        tiny_model_path: Path, tmp_path: Path) -> None:
    huge = keras_with_input_shape(tiny_model_path, tmp_path / "huge_input.keras",
                                  [None, 100_000, 100_000, 3])
    with pytest.raises(ModelBoundsError) as refused:
        read_model(huge)
    assert str(refused.value) == (
        f"{huge}: its layer configuration declares a tensor of shape [None, 100000, 100000, 3] "
        f"(30,000,000,000 values a sample); the limit is {MAX_SAMPLE_VALUES:,}; not loaded")


def test_real_models_still_load(tiny_model_path: Path, tiny_h5_path: Path) -> None:
    for path in (tiny_model_path, tiny_h5_path):
        assert read_model(path).count_params() > 0
