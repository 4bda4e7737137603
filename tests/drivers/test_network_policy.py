"""The network policy: PI speed control against hand computation, a real Keras model."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from clonedrive.drivers.policy import NetworkPolicy, Policy, SpeedController, load_policy
from clonedrive.network.model_file import load_model


def test_pi_matches_drive_py_by_hand() -> None:
    controller = SpeedController(9.0)
    # drive.py: e = set - speed; integral += e; throttle = 0.1 e + 0.002 integral
    assert controller.update(0.0) == pytest.approx(0.1 * 9 + 0.002 * 9)  # 0.918
    assert controller.update(4.0) == pytest.approx(0.1 * 5 + 0.002 * 14)  # 0.528
    assert controller.update(10.0) == pytest.approx(0.1 * -1 + 0.002 * 13)  # -0.074
    assert controller.integral_mph == pytest.approx(13.0)
    controller.reset()
    assert controller.update(9.0) == 0.0


def test_pi_anti_windup() -> None:
    controller = SpeedController(30.0)
    # e = 30 -> 0.1 * 30 = 3 saturates: the error is not summed and the output is clipped.
    for _ in range(100):
        assert controller.update(0.0) == 1.0
    assert controller.integral_mph == 0.0
    # Reaching the set speed, the output is 0 at once: nothing was wound up.
    assert controller.update(30.0) == 0.0
    # Far over speed: saturated braking, again without winding up.
    assert controller.update(50.0) == -1.0
    assert controller.integral_mph == 0.0
    # Near the set point it integrates as drive.py does.
    assert controller.update(28.0) == pytest.approx(0.1 * 2 + 0.002 * 2)


def test_pi_integrates_when_the_error_unwinds_saturation() -> None:
    controller = SpeedController(9.0)
    controller.integral_mph = 600.0  # 0.002 * 600 = 1.2: saturated high
    # A negative error brings the output back inside: it is summed.
    assert controller.update(19.0) == pytest.approx(0.1 * -10 + 0.002 * 590)
    assert controller.integral_mph == pytest.approx(590.0)


def frames(count: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.integers(0, 256, size=(count, 160, 320, 3), dtype=np.uint8)


def test_policy_protocol_and_act(tiny_model) -> None:
    policy = NetworkPolicy(tiny_model, set_speed_mph=9.0)
    as_policy: Policy = policy  # NetworkPolicy satisfies the Policy protocol
    assert callable(as_policy.reset) and callable(as_policy.act)
    image = frames(1, 0)[0]
    steering, throttle = policy.act(image, 0.0)
    want = float(np.asarray(tiny_model.predict_on_batch(image[None].astype(np.float32)))[0, 0])
    assert isinstance(steering, float) and isinstance(throttle, float)
    assert steering == pytest.approx(want, abs=1e-6)
    assert throttle == pytest.approx(0.918)
    policy.reset()
    assert policy.act(image, 0.0)[1] == pytest.approx(0.918)


def test_predict_steering_matches_act(tiny_model) -> None:
    policy = NetworkPolicy(tiny_model)
    images = frames(7, 1)
    batch = policy.predict_steering(images)
    assert batch.shape == (7,) and batch.dtype == np.float32
    single = [policy.act(image, 9.0)[0] for image in images]
    np.testing.assert_array_equal(batch, np.float32(single))
    assert policy.predict_steering(images[:0]).shape == (0,)


@pytest.mark.parametrize("mirror_average", [False, True])
def test_a_frames_prediction_does_not_depend_on_the_frames_beside_it(mirror_average) -> None:
    """Each frame goes through the network alone, as drive.py's one frame: the same bits in any
    batch, at any position, beside any frames. (A batched convolution rounds differently at
    each batch size; the closed loop amplifies it, so a car beside others drove another path.)"""
    from clonedrive.model.architectures import build_model

    policy = NetworkPolicy(build_model("fast", seed=5, speed_head=True),
                           mirror_average=mirror_average)
    images = frames(12, 23)
    steering, speed = policy.predict(images)
    for index in (0, 5, 11):
        alone_steering, alone_speed = policy.predict(images[index:index + 1])
        assert alone_steering[0] == steering[index] and alone_speed[0] == speed[index]
    others = np.concatenate([frames(3, 24), images[5:6], frames(8, 25)])
    assert policy.predict(others)[0][3] == steering[5]
    assert policy.predict(images[::-1])[0][6] == steering[5]


def test_inputs_are_validated(tiny_model) -> None:
    policy = NetworkPolicy(tiny_model)
    with pytest.raises(ValueError, match="160, 320, 3"):
        policy.act(np.zeros((160, 320, 3), dtype=np.float32), 0.0)
    with pytest.raises(ValueError, match="160, 320, 3"):
        policy.act(np.zeros((320, 160, 3), dtype=np.uint8), 0.0)
    with pytest.raises(ValueError):
        policy.predict_steering(np.zeros((160, 320, 3), dtype=np.uint8))


def constant_model(value: float):
    """A model whose steering is ``value`` for every image (to test clipping and speed)."""
    import keras
    from keras import layers

    inputs = keras.Input(shape=(160, 320, 3))
    x = layers.GlobalAveragePooling2D()(inputs)
    outputs = layers.Dense(1, kernel_initializer="zeros", bias_initializer="zeros")(x)
    model = keras.Model(inputs, outputs)
    model.layers[-1].set_weights([np.zeros((3, 1), np.float32), np.array([value], np.float32)])
    return model


def test_steering_is_clipped() -> None:
    image = frames(1, 2)[0]
    assert NetworkPolicy(constant_model(3.0)).act(image, 9.0)[0] == 1.0
    assert NetworkPolicy(constant_model(-2.0)).act(image, 9.0)[0] == -1.0


def test_slow_in_curves_lowers_the_target_speed() -> None:
    image = frames(1, 3)[0]
    straight = NetworkPolicy(constant_model(0.0), 20.0, slow_in_curves=True)
    bend = NetworkPolicy(constant_model(0.2), 20.0, slow_in_curves=True)
    hairpin = NetworkPolicy(constant_model(-0.9), 20.0, slow_in_curves=True)
    assert straight.target_speed_mph(0.0) == 20.0
    assert bend.target_speed_mph(0.2) == pytest.approx(20.0 * 0.7)
    assert hairpin.target_speed_mph(-0.9) == pytest.approx(20.0 * 0.4)
    assert bend.target_speed_mph(0.2, set_speed_mph=10.0) == pytest.approx(10.0 * 0.7)
    # At 14 mph: straight still accelerates, the bend holds (target 14), the hairpin brakes.
    assert straight.act(image, 14.0)[1] == pytest.approx(0.1 * 6 + 0.002 * 6)
    assert bend.act(image, 14.0)[1] == pytest.approx(0.0, abs=1e-6)
    assert hairpin.act(image, 14.0)[1] == pytest.approx(0.1 * -6 + 0.002 * -6)
    plain = NetworkPolicy(constant_model(-0.9), 20.0)
    assert plain.target_speed_mph(-0.9) == 20.0


@pytest.mark.parametrize("suffix", [".keras", ".h5"])
def test_load_policy(tmp_path: Path, tiny_model, suffix: str) -> None:
    path = tmp_path / f"model{suffix}"
    tiny_model.save(path)
    policy = load_policy(path, set_speed_mph=15.0, slow_in_curves=True)
    assert policy.set_speed_mph == 15.0 and policy.slow_in_curves
    images = frames(2, 4)
    want = np.asarray(tiny_model.predict_on_batch(images.astype(np.float32)))[:, 0]
    np.testing.assert_allclose(policy.predict_steering(images), want, atol=1e-6)


def test_load_errors(tmp_path: Path) -> None:
    import keras
    from keras import layers

    with pytest.raises(FileNotFoundError, match="missing.keras"):
        load_model(tmp_path / "missing.keras")
    (tmp_path / "model.txt").write_text("x")
    with pytest.raises(ValueError, match=r"\.keras, \.h5 or \.onnx"):
        load_model(tmp_path / "model.txt")
    (tmp_path / "broken.keras").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="broken.keras"):
        load_model(tmp_path / "broken.keras")
    # Lambda layers can run arbitrary code: safe_mode refuses them.
    inputs = keras.Input(shape=(160, 320, 3))
    x = layers.Lambda(lambda t: t / 255.0)(inputs)
    outputs = layers.Dense(1)(layers.GlobalAveragePooling2D()(x))
    keras.Model(inputs, outputs).save(tmp_path / "lambda.keras")
    with pytest.raises(ValueError, match="lambda.keras"):
        load_model(tmp_path / "lambda.keras")
    # The model must take the center camera.
    small = keras.Input(shape=(66, 200, 3))
    keras.Model(small, layers.Dense(1)(layers.Flatten()(small))).save(tmp_path / "nvidia.keras")
    with pytest.raises(ValueError, match=r"\(66, 200, 3\)"):
        load_model(tmp_path / "nvidia.keras")


def test_steering_filter_is_a_first_order_low_pass() -> None:
    from clonedrive.drivers.policy import SteeringFilter

    passthrough = SteeringFilter(0.0)
    assert [passthrough.update(v) for v in (0.5, -0.5)] == [0.5, -0.5]
    hand = SteeringFilter(0.1, control_hz=15.0)  # alpha = (1/15) / (0.1 + 1/15) = 0.4
    assert hand.update(0.0) == 0.0
    assert hand.update(1.0) == pytest.approx(0.4)
    assert hand.update(1.0) == pytest.approx(0.64)
    hand.reset()
    assert hand.update(1.0) == 1.0  # a new episode starts from the first command
    with pytest.raises(ValueError, match=">= 0"):
        SteeringFilter(-1.0)
    policy = NetworkPolicy(constant_model(0.5), steering_filter_s=0.1)
    image = frames(1, 4)[0]
    assert policy.act(image, 9.0)[0] == pytest.approx(0.5)  # first command passes
    policy.steering_filter.reset()
    policy.steering_filter.update(0.0)
    assert policy.act(image, 9.0)[0] == pytest.approx(0.2)


def test_steering_hold_keeps_the_wheel_through_small_jitter_without_delay() -> None:
    from clonedrive.drivers.policy import SteeringFilter

    hold = SteeringFilter(hold=0.05)
    jitter = [0.10, 0.13, 0.08, 0.12, 0.09]  # within 0.05 of the wheel: it stays
    assert [hold.update(v) for v in jitter] == [0.10] * 5
    # A real move: the wheel follows at once, staying 0.05 behind, never further.
    assert hold.update(0.40) == pytest.approx(0.35)
    assert hold.update(0.45) == pytest.approx(0.40)
    assert hold.update(0.38) == pytest.approx(0.40)  # back within the hold
    assert hold.update(-0.20) == pytest.approx(-0.15)
    wheel = SteeringFilter(hold=0.05)
    rng = np.random.default_rng(0)
    predictions = np.sin(np.linspace(0, 6, 300)) * 0.5 + rng.normal(0, 0.02, 300)
    held = np.array([wheel.update(v) for v in predictions])
    assert np.max(np.abs(held - predictions)) <= 0.05 + 1e-12
    # Far less wheel movement than the jittery prediction.
    assert np.abs(np.diff(held)).sum() < 0.5 * np.abs(np.diff(predictions)).sum()
    combined = SteeringFilter(0.1, control_hz=15.0, hold=0.05)
    assert combined.update(0.0) == 0.0
    assert combined.update(1.0) == pytest.approx(0.35)  # low-pass 0.4, then the hold
    with pytest.raises(ValueError, match="hold"):
        SteeringFilter(hold=-0.1)
    with pytest.raises(ValueError, match="hold"):
        SteeringFilter(hold=float("nan"))
    policy = NetworkPolicy(constant_model(0.5), steering_filter_s=0.3, steering_hold=0.02,
                           slow_in_curves=True, curve_gain=2.0)
    again = NetworkPolicy(constant_model(0.5), **policy.options())
    assert again.options() == policy.options()
    assert (again.steering_hold, again.steering_filter_s, again.curve_gain) == (0.02, 0.3, 2.0)


def test_steering_scale_from_turns_the_car_no_faster_than_at_that_speed() -> None:
    from clonedrive.drivers.policy import SteeringFilter

    wheel = SteeringFilter(scale_from_mph=24.0)
    assert wheel.update(0.5, speed_mph=15.0) == 0.5  # below: as predicted
    assert wheel.update(0.5, speed_mph=24.0) == 0.5
    assert wheel.update(0.5, speed_mph=30.0) == pytest.approx(0.4)  # 24 / 30
    assert wheel.update(-0.3, speed_mph=48.0) == pytest.approx(-0.15)
    # The car's speed times its turn rate per unit of steering stays at 24 mph's.
    for speed in (30.0, 40.0, 60.0):
        assert wheel.update(1.0, speed_mph=speed) * speed == pytest.approx(24.0)
    # No speed, or one that is not a number: not scaled.
    assert wheel.update(0.5) == 0.5 and wheel.update(0.5, speed_mph=float("nan")) == 0.5
    assert wheel.update(0.5, speed_mph=float("inf")) == 0.5
    # Off by default and at 0, as drive.py.
    assert SteeringFilter().update(0.5, speed_mph=80.0) == 0.5
    # Scaled before the low-pass and the hold: the hold acts on the scaled prediction.
    combined = SteeringFilter(hold=0.05, scale_from_mph=20.0)
    assert combined.update(0.5, speed_mph=40.0) == pytest.approx(0.25)
    assert combined.update(0.55, speed_mph=40.0) == pytest.approx(0.25)  # 0.275: held
    for bad in (-1.0, 2.0, 101.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="steering_scale_from_mph"):
            SteeringFilter(scale_from_mph=bad)
    policy = NetworkPolicy(constant_model(0.5), steering_scale_from_mph=20.0)
    assert policy.act(np.zeros((160, 320, 3), np.uint8), 40.0)[0] == pytest.approx(0.25)
    assert NetworkPolicy(constant_model(0.5), **policy.options()).steering_scale_from_mph == 20.0
    assert policy.driving_settings().steering_scale_from_mph == 20.0


@pytest.fixture(scope="module")
def speed_head_model():
    """A small untrained network with a speed head (its policies only read it)."""
    from clonedrive.model.architectures import build_model

    return build_model("fast", seed=5, speed_head=True)


def test_mirror_average_takes_the_mean_with_the_mirror_images_prediction(
        speed_head_model) -> None:
    model = speed_head_model
    plain = NetworkPolicy(model)
    mirrored = NetworkPolicy(model, mirror_average=True)
    images = frames(5, 11)
    steering, speed = plain.predict(images)
    steering_flip, speed_flip = plain.predict(np.ascontiguousarray(images[:, :, ::-1]))
    got_steering, got_speed = mirrored.predict(images)
    # Steering of the mirror image is negated (the road bends the other way), speed is not.
    np.testing.assert_allclose(got_steering, (steering - steering_flip) / 2, atol=1e-6)
    np.testing.assert_allclose(got_speed, (speed + speed_flip) / 2, atol=1e-4)
    assert not np.allclose(steering, steering_flip)  # the two views really differ
    # A frame that is its own mirror image steers straight, whatever the network thinks.
    symmetric = images[:1].copy()
    symmetric[:, :, 160:] = symmetric[:, :, :160][:, :, ::-1]
    assert plain.predict_steering(symmetric)[0] != pytest.approx(0.0, abs=1e-4)
    assert mirrored.predict_steering(symmetric)[0] == pytest.approx(0.0, abs=1e-6)
    # act() steers with the same averaged prediction; options carry the setting.
    assert mirrored.act(images[0], 20.0)[0] == pytest.approx(float(got_steering[0]), abs=1e-6)
    assert NetworkPolicy(model, **mirrored.options()).mirror_average is True
    assert plain.options()["mirror_average"] is False


def test_full_speed_at_stretches_the_top_of_the_learned_speed(speed_head_model) -> None:
    model = speed_head_model
    learned = NetworkPolicy(model, 30.0)
    stretched = NetworkPolicy(model, 30.0, full_speed_at=0.9)
    # A target at or above 0.9 of the set speed drives at the set speed ...
    assert learned.target_speed_mph(0.0, learned_speed_mph=27.0) == 27.0
    assert stretched.target_speed_mph(0.0, learned_speed_mph=27.0) == pytest.approx(30.0)
    assert stretched.target_speed_mph(0.0, learned_speed_mph=29.0) == 30.0  # the cap holds
    # ... between 0.8 and 0.9 of it linearly (24 -> 24, 25.5 -> 27, 27 -> 30) ...
    assert stretched.target_speed_mph(0.0, learned_speed_mph=25.5) == pytest.approx(27.0)
    # ... and braking below 0.8 of it (a tight bend) stays as learned, at any set speed.
    assert stretched.target_speed_mph(0.0, learned_speed_mph=20.0) == 20.0
    assert stretched.target_speed_mph(0.0, set_speed_mph=15.0,
                                      learned_speed_mph=11.0) == 11.0
    assert stretched.target_speed_mph(0.0, set_speed_mph=15.0,
                                      learned_speed_mph=13.5) == pytest.approx(15.0)
    # After the scale: 24.3 x 1.05 = 25.515 -> 24 + 1.515 x 2.
    both = NetworkPolicy(model, 30.0, speed_scale=1.05, full_speed_at=0.9)
    assert both.target_speed_mph(0.0, learned_speed_mph=24.3) == pytest.approx(27.03)
    assert NetworkPolicy(model, **stretched.options()).full_speed_at == 0.9
    assert stretched.driving_settings().full_speed_at == 0.9
    for bad in (0.8, 1.2, float("nan")):
        with pytest.raises(ValueError, match="full_speed_at"):
            NetworkPolicy(model, full_speed_at=bad)


def test_speed_scale_multiplies_the_learned_target_speed_under_the_cap(
        speed_head_model) -> None:
    model = speed_head_model
    learned = NetworkPolicy(model, 30.0)
    faster = NetworkPolicy(model, 30.0, speed_scale=1.05)
    assert learned.target_speed_mph(0.1, learned_speed_mph=20.0) == 20.0
    assert faster.target_speed_mph(0.1, learned_speed_mph=20.0) == pytest.approx(21.0)
    assert faster.target_speed_mph(0.1, learned_speed_mph=29.0) == 30.0  # the cap holds
    # The floor and the set speed alone (no learned speed) are not scaled.
    assert faster.target_speed_mph(0.1, learned_speed_mph=1.0) == pytest.approx(0.4 * 30.0)
    assert faster.target_speed_mph(0.1) == 30.0
    # Options (another process's policy) and the driving settings carry the scale.
    assert NetworkPolicy(model, **faster.options()).speed_scale == 1.05
    assert faster.driving_settings().speed_scale == 1.05
    with pytest.raises(ValueError, match="speed_scale"):
        NetworkPolicy(model, speed_scale=3.0)


def test_caution_slows_where_a_frame_and_its_mirror_image_disagree(speed_head_model) -> None:
    model = speed_head_model
    images = frames(6, 13)
    plain = NetworkPolicy(model)
    careful = NetworkPolicy(model, 30.0, mirror_average=True, caution=40.0, caution_from=0.01)
    # The disagreement is half the gap between the frame's steering and its mirror image's
    # (negated): how far each view is from the steering driven.
    steering = plain.predict_steering(images)
    steering_flip = plain.predict_steering(np.ascontiguousarray(images[:, :, ::-1]))
    careful.predict(images)
    np.testing.assert_allclose(careful.last_disagreement, np.abs(steering + steering_flip) / 2,
                               atol=1e-6)
    assert careful.last_disagreement.shape == (6,) and careful.last_disagreement.max() > 0
    plain.predict(images)
    assert not plain.last_disagreement.any()  # one view: nothing to disagree with
    # Below caution_from nothing changes; above it the target is divided by 1 + C x excess.
    assert careful.target_speed_mph(0.0, learned_speed_mph=25.0, disagreement=0.01) == 25.0
    assert careful.target_speed_mph(0.0, learned_speed_mph=25.0,
                                    disagreement=0.035) == pytest.approx(12.5)
    assert careful.target_speed_mph(0.0, disagreement=0.035) == pytest.approx(15.0)
    # Never below the floor; a non-finite disagreement does not slow.
    assert careful.target_speed_mph(0.0, learned_speed_mph=25.0,
                                    disagreement=1.0) == pytest.approx(12.0)
    assert careful.target_speed_mph(0.0, learned_speed_mph=25.0,
                                    disagreement=float("nan")) == 25.0
    # act() slows for the frame it sees; options and settings carry both numbers.
    careful.act(images[0], 0.0)
    learned = float(careful.predict(images[:1])[1][0])
    want = careful.target_speed_mph(careful.steering_filter.steering, learned_speed_mph=learned,
                                    disagreement=float(careful.last_disagreement[0]))
    assert careful.controller.set_speed_mph == pytest.approx(want)
    again = NetworkPolicy(model, **careful.options())
    assert (again.caution, again.caution_from) == (40.0, 0.01)
    assert careful.driving_settings().caution == 40.0


def test_caution_needs_mirror_averaging_and_a_number_in_range(speed_head_model) -> None:
    # Without mirror averaging there is nothing to compare: a file's caution does nothing.
    single = NetworkPolicy(speed_head_model, 30.0, caution=10.0)
    single.predict(frames(2, 3))
    assert single.target_speed_mph(0.0, learned_speed_mph=25.0,
                                   disagreement=float(single.last_disagreement[0])) == 25.0
    for bad in (-1.0, 101.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="caution"):
            NetworkPolicy(speed_head_model, mirror_average=True, caution=bad)
    for bad in (-0.01, 0.2, float("nan")):
        with pytest.raises(ValueError, match="caution_from"):
            NetworkPolicy(speed_head_model, mirror_average=True, caution=1.0, caution_from=bad)
