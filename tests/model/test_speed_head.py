"""The speed head: a second, named output trained from the expert's target speed, used by the
network policy capped by the set speed, refused when misnamed."""

from __future__ import annotations

import csv
import dataclasses
from pathlib import Path

import keras
import numpy as np
import pytest

from clonedrive.data.recorder import RecordConfig, record
from clonedrive.drivers.policy import NetworkPolicy, load_policy
from clonedrive.model.architectures import MODEL_NAMES, build_model
from clonedrive.model.train import train
from clonedrive.model.train_config import TrainConfig
from clonedrive.network.contract import (
    SPEED_OUTPUT,
    TARGET_SPEED_SCALE_MPH,
    check_model,
    has_speed_head,
)

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity"


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_every_architecture_can_have_a_named_speed_head(name) -> None:
    plain = build_model(name, seed=3)
    headed = build_model(name, seed=3, speed_head=True)
    assert headed.output_names == ["steering", SPEED_OUTPUT]
    assert has_speed_head(headed) and not has_speed_head(plain)
    check_model(headed)
    # The shared layers and the steering output start from the same weights.
    for layer in plain.layers:
        for mine, theirs in zip(layer.get_weights(), headed.get_layer(layer.name).get_weights(),
                                strict=True):
            np.testing.assert_array_equal(mine, theirs)
    outputs = headed.predict_on_batch(np.zeros((2, 160, 320, 3), np.float32))
    assert [np.asarray(out).shape for out in outputs] == [(2, 1), (2, 1)]


def constant_two_output_model(steering: float, speed: float, second_name: str = SPEED_OUTPUT):
    from keras import layers

    inputs = keras.Input(shape=(160, 320, 3))
    x = layers.GlobalAveragePooling2D()(inputs)
    heads = []
    for name, value in (("steering", steering), (second_name, speed)):
        dense = layers.Dense(1, name=name)
        heads.append(dense(x))
        dense.set_weights([np.zeros((3, 1), np.float32), np.array([value], np.float32)])
    return keras.Model(inputs, heads)


def test_policy_aims_for_the_learned_speed_capped_by_the_set_speed() -> None:
    image = np.zeros((160, 320, 3), np.uint8)
    half = NetworkPolicy(constant_two_output_model(0.1, 0.5), set_speed_mph=30.0)
    assert half.speed_head
    steering, learned = half.predict(np.stack([image, image]))
    np.testing.assert_allclose(steering, [0.1, 0.1], rtol=1e-6)
    np.testing.assert_allclose(learned, [0.5 * TARGET_SPEED_SCALE_MPH] * 2, rtol=1e-6)
    # At 15 mph the target is the learned 15 mph: no throttle.
    assert half.act(image, 15.0) == (pytest.approx(0.1), pytest.approx(0.0, abs=1e-6))
    assert half.target_speed_mph(0.1, set_speed_mph=10.0, learned_speed_mph=15.0) == 10.0
    # Never below the floor (40 % of the set speed); NaN means "no opinion": the set speed.
    assert half.target_speed_mph(0.0, learned_speed_mph=0.0) == pytest.approx(12.0)
    nan = NetworkPolicy(constant_two_output_model(0.0, float("nan")), set_speed_mph=20.0)
    assert nan.predict(image[None])[1][0] == pytest.approx(TARGET_SPEED_SCALE_MPH)
    # slow_in_curves still works on top: the lower of the two.
    both = NetworkPolicy(constant_two_output_model(0.4, 1.0), 30.0, slow_in_curves=True)
    assert both.target_speed_mph(0.4, learned_speed_mph=30.0) == pytest.approx(12.0)


def test_models_with_an_unknown_second_output_are_refused(tmp_path) -> None:
    with pytest.raises(ValueError, match="must be named 'target_speed'"):
        check_model(constant_two_output_model(0.0, 0.5, second_name="throttle"))
    model = constant_two_output_model(0.0, 0.5, second_name="throttle")
    model.save(tmp_path / "odd.keras")
    with pytest.raises(ValueError, match="target_speed"):
        load_policy(tmp_path / "odd.keras")


@pytest.mark.slow
def test_training_with_both_losses_learns_the_speed_and_drives(tmp_path) -> None:
    recording = tmp_path / "expert"
    record(RecordConfig(track="mountain", seconds=4.0, speed_mph=20.0, scenery=False,
                        start_time="2026-11-21T10:11:12.345"), recording, progress=False)
    udacity = FIXTURES / "mountain_windows_paths"  # no sidecar: recorded speed stands in
    config = TrainConfig(model="fast", batch_size=64, epochs=2, learning_rate=1e-3,
                         speed_head=True, export_h5=False)
    result = train(config, [recording, udacity], tmp_path / "run", progress=False)
    assert result.dataset["rows_with_target_speed"] == 60
    with open(tmp_path / "run" / "history.csv", encoding="utf-8") as handle:
        history = list(csv.DictReader(handle))
    assert list(history[0]) == ["epoch", "loss", "val_loss", "mse", "val_mse", "seconds",
                                "speed_mse", "val_speed_mse"]
    assert all(np.isfinite(float(row[key])) for row in history
               for key in ("mse", "speed_mse", "val_speed_mse"))
    policy = load_policy(result.model_path, set_speed_mph=30.0)
    assert policy.speed_head
    _, learned = policy.predict(np.zeros((1, 160, 320, 3), np.uint8))
    assert 0.0 <= learned[0] <= TARGET_SPEED_SCALE_MPH

    # A one-output run continues as a speed-head run from its weights (layers by name).
    plain = train(dataclasses.replace(config, speed_head=False, epochs=1), [recording],
                  tmp_path / "plain", progress=False)
    warm = train(dataclasses.replace(config, epochs=1, init_from=str(plain.model_path)),
                 [recording], tmp_path / "warm", progress=False)
    assert has_speed_head(keras.saving.load_model(warm.model_path, safe_mode=True))


def test_evaluate_drives_a_speed_head_model_at_its_learned_speed(tmp_path) -> None:
    from clonedrive.evaluate.rollout import EvalConfig, evaluate

    policy = NetworkPolicy(constant_two_output_model(0.0, 0.4))  # learned: 12 mph
    config = EvalConfig(tracks=("lake",), speeds_mph=(30.0,), laps=1, max_seconds=12.0,
                        scenery=False)
    report = evaluate(policy, config, tmp_path, progress=False)
    assert report["speed_head"] is True and "learned" in report["speed_control"]
    run = report["runs"][0]
    assert 8.0 < run["mean_speed_mph"] < 12.5  # held near 12 mph although the cap is 30


def test_the_censored_speed_loss_reads_top_speed_labels_as_lower_bounds() -> None:
    from clonedrive.model.losses import censored_speed_mse, speed_loss

    y_true = np.array([[1.0], [1.0], [0.5], [0.5]], np.float32)
    y_pred = np.array([[1.3], [0.8], [0.7], [0.3]], np.float32)
    loss = keras.ops.convert_to_numpy(censored_speed_mse(y_true, y_pred))
    # above a top-speed label: free; below it and either side of a lower label: squared error
    np.testing.assert_allclose(loss, [0.0, 0.04, 0.04, 0.04], atol=1e-6)
    assert speed_loss("mse") == "mse" and speed_loss("censored") is censored_speed_mse
    with pytest.raises(ValueError, match="speed loss 'huber'"):
        speed_loss("huber")
    with pytest.raises(ValueError, match="speed_loss 'huber'; expected one of: mse, censored"):
        TrainConfig(speed_loss="huber")


def test_a_censored_speed_head_run_trains_resumes_and_loads(tmp_path) -> None:
    recording = tmp_path / "expert"
    record(RecordConfig(track="lake", seconds=4.0, speed_mph=30.0, scenery=False,
                        start_time="2026-11-21T10:11:12.345"), recording, progress=False)
    config = TrainConfig(model="fast", batch_size=32, epochs=1, learning_rate=1e-3,
                         speed_head=True, speed_loss="censored", export_h5=False)
    train(config, [recording], tmp_path / "run", progress=False)
    resumed = train(dataclasses.replace(config, epochs=2), [recording], tmp_path / "run",
                    resume=True, progress=False)
    assert resumed.epochs_done == 2
    assert all(np.isfinite(row["speed_mse"]) for row in resumed.history)
    policy = load_policy(resumed.model_path, set_speed_mph=30.0)
    assert policy.speed_head


def test_headroom_continues_the_braking_profile_above_the_top_speed() -> None:
    from clonedrive.data.speed_labels import with_headroom
    from clonedrive.drivers.expert import ExpertConfig
    from clonedrive.world.vehicle import MPH_TO_MPS

    top = TARGET_SPEED_SCALE_MPH
    # One recording at 15 Hz and the top speed: open road, a bend at 15 mph (rows 40-49), open road.
    rows = np.arange(60)
    labels = np.where((rows >= 40) & (rows < 50), 15.0, top).astype(np.float32)
    # Every row twice (a camera and its mirror image), and a second recording beside it.
    recording = np.r_[np.zeros(120, np.int32), np.ones(60, np.int32)]
    row = np.r_[np.repeat(rows, 2), rows]
    time_s = row / 15.0
    speed = np.full(180, top, np.float32)
    given = np.r_[np.repeat(labels, 2), np.full(60, top, np.float32)]
    out, raised = with_headroom(given, recording, row, time_s, speed, 1.2)
    assert raised == 2 * 50 + 60
    first = out[:120:2]
    np.testing.assert_array_equal(first, out[1:120:2])  # a row's samples keep one label
    np.testing.assert_array_equal(first[40:50], 15.0)  # the bend: unchanged
    np.testing.assert_allclose(first[50:], 1.2 * top)  # no bend ahead: the ceiling
    np.testing.assert_allclose(out[120:], 1.2 * top)  # the other recording sees no bend
    metres_to_bend = (40 - rows[:40]) * top * MPH_TO_MPS / 15.0
    reach = np.sqrt((15.0 * MPH_TO_MPS) ** 2 + 2 * ExpertConfig().brake_decel_mps2 *
                    metres_to_bend) / MPH_TO_MPS
    np.testing.assert_allclose(first[:40], np.clip(reach, top, 1.2 * top), rtol=1e-5)
    assert first[2] > first[5] > first[12] > top == first[20] == first[39]  # a smooth rise
    unchanged, _ = with_headroom(given, recording, row, time_s, speed, 1.0)
    np.testing.assert_allclose(unchanged, given)
    for bad in (0.9, 2.5, float("nan")):
        with pytest.raises(ValueError, match="speed_headroom must be in"):
            TrainConfig(speed_headroom=bad)


@pytest.mark.parametrize("balance", [False, True])
def test_a_headroom_run_trains_its_top_speed_labels_above_the_cap(tmp_path, balance) -> None:
    from clonedrive.data.speed_labels import read_speed_labels

    recording = tmp_path / "expert"
    record(RecordConfig(track="lake", seconds=4.0, speed_mph=30.0, scenery=False,
                        start_time="2026-11-21T10:11:12.345"), recording, progress=False)
    labels = np.array(list(read_speed_labels(recording).speeds_mph.values()))
    at_top = int(np.sum(labels >= 0.999 * TARGET_SPEED_SCALE_MPH))
    assert 0 < at_top
    config = TrainConfig(model="fast", batch_size=32, epochs=1, learning_rate=1e-3,
                         speed_head=True, speed_headroom=1.25, export_h5=False,
                         balance=balance, correction=0.2)
    result = train(config, [recording], tmp_path / "run", progress=False)
    dataset = result.dataset
    if balance:  # balancing drops samples, but only after the profile has seen them all
        assert dataset["samples_after_balance"] < dataset["samples_before_balance"]
    # every camera and its mirrored copy of a row at the top speed: 3 x 2 samples per row
    assert dataset["speed_labels_raised"] == 6 * at_top
    policy = load_policy(result.model_path, set_speed_mph=30.0)
    assert policy.speed_head  # a head trained above the cap loads and drives like any other
