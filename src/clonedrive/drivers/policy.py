"""The network policy: a Keras steering model plus a PI speed controller, as Udacity's drive.py.

The model (its contract: :mod:`clonedrive.network.contract`) takes the center camera as RGB
uint8-valued ``(160, 320, 3)`` and predicts steering in [-1, 1] (= wheel angle / 25 deg).
Throttle comes from :class:`SpeedController`, which holds a target speed in mph.

For a model with a **speed head** (a second output,
:data:`~clonedrive.network.contract.SPEED_OUTPUT`), :class:`NetworkPolicy` aims for the learned
speed, capped by the set speed; a one-output model drives at the set speed (or with
``slow_in_curves``, the hand-made rule).

Model files (``.keras``, ``.h5`` including students' Keras 1/2 files, ``.onnx``) are read and
checked by :func:`clonedrive.network.model_file.load_model`; :func:`load_policy` here is the
entry point every command that drives uses (``trust``: ``--trust-model``; ``runtime``:
``--runtime``), with the driving settings stored in the file
(:mod:`clonedrive.network.driving_settings`).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from clonedrive.base.udacity_spec import CONTROL_HZ, IMAGE_SHAPE, SET_SPEED_MPH, SPEED_KI, SPEED_KP
from clonedrive.network.contract import TARGET_SPEED_SCALE_MPH, check_model, has_speed_head
from clonedrive.network.crop import visible_rows
from clonedrive.network.driving_settings import (
    STRETCH_FROM,
    DrivingSettings,
    check_caution,
    check_caution_from,
    check_caution_needs_mirror,
    check_full_speed_at,
    check_speed_scale,
    check_steering_filter_s,
    check_steering_hold,
    check_steering_scale_from,
)
from clonedrive.network.traced import PortableModel, TracedForward, forward_for, tensor_dtype

if TYPE_CHECKING:
    import keras


#: How :meth:`NetworkPolicy.predict` puts frames through the network, as bench.json records it
#: (``prediction``): runs made another way differ from these by the last bits of each
#: prediction, which a closed loop amplifies into a slightly different path.
PREDICTION = "each frame alone"
#: What a bench.json without ``prediction`` is taken to mean: the code before 2026-12-07
#: batched the lock-step cars' frames (runs made on 2026-12-07 between commits 99929f5 and
#: 5629524 predicted each frame alone without saying so).
PREDICTION_BEFORE = "not recorded (lock-step cars' frames batched, before 2026-12-07)"


class Policy(Protocol):
    """Anything that drives from the center camera: the network, a recorded replay, a test.

    A policy that keeps state per car (a speed controller, a filter) also has ``fork()``,
    returning a fresh policy for another car (:meth:`NetworkPolicy.fork`); the drive server
    calls it once per connection, and shares a policy without one between connections."""

    def reset(self) -> None: ...

    def act(self, image_rgb: np.ndarray, speed_mph: float) -> tuple[float, float]:
        """``(steering [-1, 1], throttle [-1, 1])`` for one uint8 RGB (160, 320, 3) frame."""
        ...


class SpeedController:
    """PI speed controller: ``throttle = kp * e + ki * sum(e)``, ``e = set - speed`` in mph.

    Defaults are drive.py's (kp 0.1, ki 0.002, one error sample added to the sum per call).
    Anti-windup by conditional integration: an error is not added to the sum when doing so
    would leave the output saturated in the error's direction; the output is clipped to [-1, 1]
    (negative throttle brakes).
    """

    def __init__(self, set_speed_mph: float = SET_SPEED_MPH, *, kp: float = SPEED_KP,
                 ki: float = SPEED_KI) -> None:
        self.set_speed_mph = set_speed_mph
        self.kp = float(kp)
        self.ki = float(ki)
        self.integral_mph = 0.0  # sum of errors over calls, mph
        self.error_mph = 0.0

    @property
    def set_speed_mph(self) -> float:
        return self._set_speed_mph

    @set_speed_mph.setter
    def set_speed_mph(self, value: float) -> None:
        value = float(value)
        if not math.isfinite(value):
            raise ValueError(f"set speed must be finite, got {value}")
        self._set_speed_mph = value

    def reset(self) -> None:
        self.integral_mph = 0.0
        self.error_mph = 0.0

    def update(self, speed_mph: float) -> float:
        """One control step: the throttle in [-1, 1] for the measured ``speed_mph``."""
        error = self._set_speed_mph - float(speed_mph)
        integral = self.integral_mph + error
        output = self.kp * error + self.ki * integral
        winding_up = (output > 1.0 and error > 0.0) or (output < -1.0 and error < 0.0)
        if not winding_up:
            self.integral_mph = integral
        self.error_mph = error
        return float(np.clip(self.kp * error + self.ki * self.integral_mph, -1.0, 1.0))


class SteeringFilter:
    """What stands between the network's steering and the wheel, per car: above
    ``scale_from_mph`` the prediction is scaled by ``scale_from_mph / speed``; then a
    first-order low-pass with ``time_constant_s`` [s] at ``control_hz`` (the expert's "hand",
    drivers.expert: 0.1 s), then a hold of ``hold`` (steering units, [-1, 1]): the wheel stays
    where it is while the (low-passed) prediction is within ``hold`` of it, and otherwise moves
    just far enough to be ``hold`` from it. The hold removes frame-to-frame jitter smaller than
    itself without the low-pass's delay: the wheel is never further than ``hold`` from the
    prediction. All 0 (the default, as drive.py): steering passes through.

    The scale: a wheel angle turns the car at a rate proportional to its speed, and a network
    does not see its speed. Above ``scale_from_mph`` a prediction turns the car as fast as it
    would at that speed, no faster: the steering loop's gain stops growing with speed (the
    expert's own gain falls with speed, drivers.expert), for a calmer wheel at the price of a
    wider line through bends taken fast."""

    def __init__(self, time_constant_s: float = 0.0, control_hz: float = CONTROL_HZ,
                 hold: float = 0.0, scale_from_mph: float = 0.0) -> None:
        self.time_constant_s = check_steering_filter_s(time_constant_s)
        self.hold = check_steering_hold(hold)
        self.scale_from_mph = check_steering_scale_from(scale_from_mph)
        period = 1.0 / float(control_hz)
        self.alpha = period / (self.time_constant_s + period)
        self.steering: float | None = None  #: the wheel: the last command handed out
        self._smoothed: float | None = None

    def reset(self) -> None:
        self.steering = None
        self._smoothed = None

    def update(self, steering: float, speed_mph: float | None = None) -> float:
        """The wheel's steering after this step's prediction ``steering`` at the car's
        ``speed_mph`` (None, or not a finite number: not scaled)."""
        steering = float(steering) * self.scale(speed_mph)
        if self._smoothed is None or self.alpha >= 1.0:
            self._smoothed = float(steering)
        else:
            self._smoothed += self.alpha * (float(steering) - self._smoothed)
        if self.steering is None:
            self.steering = self._smoothed
        else:
            self.steering = min(max(self.steering, self._smoothed - self.hold),
                                self._smoothed + self.hold)
        return self.steering

    def scale(self, speed_mph: float | None) -> float:
        """What the prediction is multiplied by at ``speed_mph``: below ``scale_from_mph``
        (or with it 0), 1."""
        if not self.scale_from_mph or speed_mph is None or not math.isfinite(speed_mph):
            return 1.0
        speed = float(speed_mph)
        return self.scale_from_mph / speed if speed > self.scale_from_mph else 1.0


def stretched_speed(learned_mph: float, set_speed_mph: float, full_speed_at: float) -> float:
    """A speed head's target ``learned_mph`` with the top of its range stretched: from
    :data:`~clonedrive.network.driving_settings.STRETCH_FROM` of ``set_speed_mph`` (unchanged)
    linearly up to ``full_speed_at`` of it (the set speed itself); above, linearly on (the set
    speed caps it later). ``full_speed_at`` 1: as learned."""
    start = STRETCH_FROM * set_speed_mph
    if full_speed_at >= 1.0 or learned_mph <= start:
        return learned_mph
    return start + (learned_mph - start) * (1.0 - STRETCH_FROM) / (full_speed_at - STRETCH_FROM)


class NetworkPolicy:
    """Steer with a Keras model; hold a target speed with :class:`SpeedController`.

    The target speed is the set speed, or for a model with a speed head (``speed_head``) the
    learned target speed capped by the set speed, and never below ``min_speed_fraction`` of it.
    ``slow_in_curves`` (off by default): the hand-made rule, the target falls as the predicted
    steering grows, ``set_speed_mph * max(min_speed_fraction, 1 - curve_gain * |steering|)``
    (40 % of the set speed at |steering| >= 0.4); with a speed head the lower of the two counts.
    ``speed_scale`` multiplies a speed head's target speed before the cap (1 by default: as
    learned). ``full_speed_at`` < 1 drives a speed head's target at or above that fraction of the
    set speed at the set speed, and stretches the targets between it and
    :data:`~clonedrive.network.driving_settings.STRETCH_FROM` of the set speed to match
    (:func:`stretched_speed`): a speed head predicts a little below the set speed through bends
    the expert takes at full speed, while its braking for tight bends, below the stretch, stays
    as learned. ``steering_filter_s`` > 0 low-passes the predicted steering and
    ``steering_hold`` > 0 holds the wheel through jitter smaller than itself, and
    ``steering_scale_from_mph`` > 0 scales the prediction by that speed over the car's above it
    (:class:`SteeringFilter`; all off by default, as drive.py). ``mirror_average`` (off by
    default) predicts on each frame and on its mirror image and averages the two (the
    mirror's steering negated, its target speed as it is): the part of the network's
    frame-to-frame noise that the two views do not share cancels, for twice the inference
    (:func:`mirrored_mean`).

    Each frame is predicted alone (:meth:`predict`), as drive.py predicts its one frame.
    """

    def __init__(
        self,
        model: keras.Model,
        set_speed_mph: float = SET_SPEED_MPH,
        slow_in_curves: bool = False,
        *,
        kp: float = SPEED_KP,
        ki: float = SPEED_KI,
        curve_gain: float = 1.5,
        min_speed_fraction: float = 0.4,
        steering_filter_s: float = 0.0,
        steering_hold: float = 0.0,
        mirror_average: bool = False,
        speed_scale: float = 1.0,
        full_speed_at: float = 1.0,
        steering_scale_from_mph: float = 0.0,
        caution: float = 0.0,
        caution_from: float = 0.0,
    ) -> None:
        check_model(model)
        self.caution = check_caution(caution)
        self.caution_from = check_caution_from(caution_from)
        self.speed_scale = check_speed_scale(speed_scale)
        self.full_speed_at = check_full_speed_at(full_speed_at)
        self.mirror_average = bool(mirror_average)
        self.steering_filter_s = float(steering_filter_s)
        self.steering_hold = float(steering_hold)
        self.steering_scale_from_mph = float(steering_scale_from_mph)
        self.steering_filter = self.new_steering_filter()
        self.model = model
        self.speed_head = has_speed_head(model)
        self.input_dtype = model_input_dtype(model)
        #: The frame rows [top, bottom) the model looks at (its first layer's Cropping2D), or
        #: None when it looks at all of them or cannot say (a traced or ONNX model).
        self.visible_rows = visible_rows(model)
        #: Runs the model on a batch: traced by PyTorch where that gives the same outputs
        #: (clonedrive.network.traced), else the model's predict_on_batch.
        self.forward = forward_for(model)
        self.set_speed_mph = float(set_speed_mph)
        self.slow_in_curves = bool(slow_in_curves)
        self.curve_gain = float(curve_gain)
        self.min_speed_fraction = float(min_speed_fraction)
        self.controller = SpeedController(set_speed_mph, kp=kp, ki=ki)
        #: Frames whose steering prediction was NaN or infinite (driven straight / at full
        #: lock instead), over this policy's life; the drive server logs it.
        self.nan_predictions = 0
        #: Which frames of the last :meth:`predict` batch had a NaN or infinite steering
        #: prediction (so a driver of several cars can count them per car).
        self.last_nonfinite = np.zeros(0, dtype=bool)
        #: Per frame of the last :meth:`predict` batch: half the gap between its steering
        #: prediction and its mirror image's (0 without ``mirror_average``).
        self.last_disagreement = np.zeros(0, dtype=np.float32)
        #: What the model file says about itself (network.driving_settings.read_notes): the
        #: recipe that made it; {} for a model given in memory or a file without notes.
        self.notes: dict = {}

    def reset(self) -> None:
        self.controller.reset()
        self.controller.set_speed_mph = self.set_speed_mph
        self.steering_filter.reset()

    def fork(self) -> NetworkPolicy:
        """A policy for another car: the same model and options (shared, not copied), with its
        own speed controller, steering filter and NaN count, all reset. The drive server gives
        each connected simulator one, so that no car's state leaks into another's."""
        car = copy.copy(self)
        car.controller = SpeedController(self.set_speed_mph, kp=self.controller.kp,
                                         ki=self.controller.ki)
        car.steering_filter = self.new_steering_filter()
        car.nan_predictions = 0
        car.last_nonfinite = np.zeros(0, dtype=bool)
        car.last_disagreement = np.zeros(0, dtype=np.float32)
        return car

    def new_steering_filter(self) -> SteeringFilter:
        """A :class:`SteeringFilter` with this policy's time constant, hold and speed scale (one
        per car)."""
        return SteeringFilter(self.steering_filter_s, hold=self.steering_hold,
                              scale_from_mph=self.steering_scale_from_mph)

    def options(self) -> dict:
        """The constructor options (other than the model and the set speed) that make another
        process's policy for the same model drive as this one does."""
        return {"kp": self.controller.kp, "ki": self.controller.ki,
                "curve_gain": self.curve_gain, "min_speed_fraction": self.min_speed_fraction,
                **self.driving_settings().options()}

    def driving_settings(self) -> DrivingSettings:
        """What stands between this policy's network and the controls: each of
        :class:`DrivingSettings`' fields is an attribute of the policy by the same name."""
        return DrivingSettings(**{field.name: getattr(self, field.name)
                                  for field in dataclasses.fields(DrivingSettings)})

    def portable(self) -> PortableModel | None:
        """This policy's model as a checked trace of the one batch it predicts (a frame, with
        its mirror image under ``mirror_average``), for a worker process to run without Keras
        (:class:`~clonedrive.network.traced.TracedModel`). None where the model does not run
        traced (ONNX Runtime, a model PyTorch cannot trace exactly)."""
        if not isinstance(self.forward, TracedForward):
            return None
        return self.forward.portable([2 if self.mirror_average else 1])

    def target_speed_mph(self, steering: float, set_speed_mph: float | None = None,
                         learned_speed_mph: float | None = None,
                         disagreement: float = 0.0) -> float:
        """The speed to aim for when the network steers ``steering`` and (with a speed head)
        predicts ``learned_speed_mph``, its steering and its mirror image's being
        ``disagreement`` apart (half the gap; ``caution`` slows for it).

        ``set_speed_mph`` defaults to this policy's set speed (an evaluator running several
        cars at different set speeds passes each car's own).
        """
        set_speed = self.set_speed_mph if set_speed_mph is None else float(set_speed_mph)
        floor = self.min_speed_fraction * set_speed
        target = set_speed
        if learned_speed_mph is not None:
            learned = stretched_speed(float(learned_speed_mph) * self.speed_scale, set_speed,
                                      self.full_speed_at)
            target = min(max(learned, floor), set_speed)
        if self.slow_in_curves:
            fraction = max(self.min_speed_fraction, 1.0 - self.curve_gain * abs(steering))
            target = min(target, set_speed * fraction)
        if self.caution and math.isfinite(disagreement):
            excess = max(0.0, disagreement - self.caution_from)
            target = max(floor, target / (1.0 + self.caution * excess))
        return target

    def act(self, image_rgb: np.ndarray, speed_mph: float) -> tuple[float, float]:
        if image_rgb.shape != IMAGE_SHAPE or image_rgb.dtype != np.uint8:
            raise ValueError(
                f"expected a uint8 RGB image of shape {IMAGE_SHAPE}, "
                f"got {image_rgb.dtype} {image_rgb.shape}"
            )
        steering, learned, _, disagreement = self._predict(image_rgb[np.newaxis])
        steer = self.steering_filter.update(float(steering[0]), speed_mph)
        self.controller.set_speed_mph = self.target_speed_mph(
            steer, learned_speed_mph=None if learned is None else float(learned[0]),
            disagreement=float(disagreement[0]))
        throttle = self.controller.update(speed_mph)
        return steer, throttle

    def predict_steering(self, images: np.ndarray) -> np.ndarray:
        """Steering in [-1, 1] for a batch of uint8 RGB frames ``(N, 160, 320, 3)`` -> ``(N,)``."""
        return self.predict(images)[0]

    def predict(self, images: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """``(steering (N,), learned target speed [mph] (N,) or None without a speed head)`` for
        N uint8 RGB frames ``(N, 160, 320, 3)``.

        Each frame goes through the network alone, as drive.py's one frame does: a batched
        convolution rounds its last bits differently at each batch size, and a closed loop
        amplifies them, so a car driven beside others (in lock-step, in a worker process's
        share of the runs, whose size follows the machine's core count) would drive a
        slightly different path than the same car driven alone. This way a frame's prediction
        depends on that frame only."""
        images = np.asarray(images)
        if images.ndim != 4 or images.shape[1:] != IMAGE_SHAPE or images.dtype != np.uint8:
            raise ValueError(
                f"expected uint8 images of shape (N, {', '.join(map(str, IMAGE_SHAPE))}), "
                f"got {images.dtype} {images.shape}"
            )
        if len(images) == 0:
            empty = np.zeros(0, dtype=np.float32)
            self.last_nonfinite = np.zeros(0, dtype=bool)
            self.last_disagreement = empty.copy()
            return empty, (empty.copy() if self.speed_head else None)
        alone = [self._predict(images[index : index + 1]) for index in range(len(images))]
        self.last_nonfinite = np.concatenate([frame[2] for frame in alone])
        self.last_disagreement = np.concatenate([frame[3] for frame in alone])
        steering = np.concatenate([frame[0] for frame in alone])
        if not self.speed_head:
            return steering, None
        return steering, np.concatenate([frame[1] for frame in alone])

    def _predict(self, images: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
        """(steering, learned speed or None, which frames' steering was NaN or infinite, the
        mirror images' disagreement on the steering: 0 without mirror averaging)."""
        # Frames go in as the model takes them: uint8 for ours (Keras and ONNX alike; a float
        # copy for ONNX Runtime would be rounded back: 7 ms per 8 frames), float32 for a model
        # with a float input. ``forward`` is predict_on_batch, or its checked trace.
        frames = images.astype(self.input_dtype, copy=False)
        if self.mirror_average:
            frames = np.concatenate([frames, frames[:, :, ::-1]])
        output = self.forward(frames)
        outputs = list(output) if isinstance(output, list | tuple) else [output]
        steering = np.asarray(outputs[0]).reshape(len(frames), -1)
        if steering.shape[1] != 1:
            raise ValueError(f"model predicts {steering.shape[1]} values per image, expected 1")
        steering = steering[:, 0].astype(np.float32)
        disagreement = np.zeros(len(images), dtype=np.float32)
        if self.mirror_average:
            disagreement = mirrored_gap(steering, sign=-1.0)
            steering = mirrored_mean(steering, sign=-1.0)
        # A NaN prediction steers straight rather than poisoning the controls; it is counted.
        nonfinite = ~np.isfinite(steering)
        self.nan_predictions += int(np.count_nonzero(nonfinite))
        steering = np.clip(np.nan_to_num(steering, nan=0.0, posinf=1.0, neginf=-1.0), -1.0, 1.0)
        disagreement = np.nan_to_num(disagreement, nan=0.0, posinf=0.0)
        if not self.speed_head:
            return steering, None, nonfinite, disagreement
        speed = np.asarray(outputs[1]).reshape(len(frames)).astype(np.float32)
        if self.mirror_average:
            speed = mirrored_mean(speed, sign=1.0)
        # A NaN speed means "no opinion": the set speed (the cap) applies.
        speed = np.nan_to_num(speed, nan=1.0, posinf=1.0, neginf=0.0)
        return (steering, np.clip(speed, 0.0, 1.0) * np.float32(TARGET_SPEED_SCALE_MPH),
                nonfinite, disagreement)


def mirrored_mean(values: np.ndarray, sign: float) -> np.ndarray:
    """``(values[:N] + sign * values[N:]) / 2`` for predictions on N frames followed by their N
    mirror images: ``sign`` -1 for the steering (a mirrored road bends the other way), +1 for
    the target speed (a bend is as sharp either way round)."""
    half = len(values) // 2
    return ((values[:half] + np.float32(sign) * values[half:]) * np.float32(0.5)).astype(
        np.float32)


def mirrored_gap(values: np.ndarray, sign: float) -> np.ndarray:
    """``|values[:N] - sign * values[N:]| / 2`` for predictions on N frames followed by their N
    mirror images: how far each frame's prediction and its mirror image's are from their
    :func:`mirrored_mean` (0 where the two views agree)."""
    half = len(values) // 2
    return (np.abs(values[:half] - np.float32(sign) * values[half:]) * np.float32(0.5)).astype(
        np.float32)


def model_input_dtype(model) -> np.dtype:
    """The dtype ``model``'s image input takes (float32 unless it says otherwise)."""
    return tensor_dtype(model.inputs[0])


def load_policy(
    path: str | Path, *, trust: bool = False, runtime: str = "auto",
    portable: PortableModel | None = None, **kwargs: object
) -> NetworkPolicy:
    """A :class:`NetworkPolicy` for the model file at ``path`` (see
    :func:`~clonedrive.network.model_file.load_model` for ``trust`` and ``runtime``), driven with
    the settings stored in the file (:mod:`clonedrive.network.driving_settings`; drive.py's where
    it has none); ``kwargs`` go to its constructor and override them, a ``None`` value leaving
    the file's setting.
    ``portable``: that model's checked traces (:meth:`NetworkPolicy.portable`), run by PyTorch
    alone instead of reading the file with Keras (a worker process's start); the same outputs
    to the last bit. The policy's ``notes`` are the file's notes (its recipe, if it has one)."""
    from clonedrive.network.driving_settings import read_notes, settings_in
    from clonedrive.network.model_file import load_model

    notes = read_notes(path)
    settings = settings_in(notes, path) or DrivingSettings()
    options = {**settings.options(), **{k: v for k, v in kwargs.items() if v is not None}}
    if kwargs.get("caution"):  # asked for, not the file's own
        check_caution_needs_mirror(options["caution"], options["mirror_average"])
    if portable is not None:
        from clonedrive.network.traced import TracedModel

        policy = NetworkPolicy(TracedModel(portable), **options)
    else:
        policy = NetworkPolicy(load_model(path, trust=trust, runtime=runtime), **options)
    policy.notes = notes
    return policy
