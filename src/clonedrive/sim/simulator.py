"""The simulator: a car on a track, stepped at the control rate with physics sub-steps.

``Simulator(track, config)`` follows the Gymnasium shape without being an Env itself:
``reset(seed, options) -> (observation, info)`` and ``step(controls) -> (observation, info)``.
The Gymnasium Env (``clonedrive.envs``) sits on top. Cameras are rendered by Panda3D only when the
configuration asks for them; the engine is owned by this object and released by :meth:`close`, or
lent by a :class:`~clonedrive.sim.camera_pool.CameraPool` (``pool=``) that shares one scene among
the simulators of a group that look alike, and given back to it by :meth:`close`.

Measurement conventions (DESIGN.md): CTE + = right of centre in the driving direction; an off-road
event is the moment any tyre's contact point leaves the road surface, checked every control step;
a lap is completed when the car crosses the start line again having covered the whole track in the
driving direction with no off-road event.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from clonedrive.base.udacity_spec import CONTROL_HZ, IMAGE_HEIGHT, IMAGE_WIDTH
from clonedrive.sim.conditions import Conditions
from clonedrive.sim.engine import DEFAULT_RENDERER, check_renderer
from clonedrive.sim.laps import LapCounter, OffRoadEvent
from clonedrive.world.catalog import load_track
from clonedrive.world.track import Track, wrap_angle
from clonedrive.world.vehicle import (
    MPH_TO_MPS,
    PHYSICS_HZ,
    Controls,
    RoadContact,
    VehicleParams,
    VehicleState,
    integrate,
    tyre_positions,
)

if TYPE_CHECKING:
    from clonedrive.sim.camera_pool import CameraPool

__all__ = ["Controls", "OffRoadEvent", "SimConfig", "SimObservation", "Simulator"]


@dataclass(frozen=True)
class SimConfig:
    """How the simulator runs. Defaults match the Udacity simulator's recording rig."""

    control_hz: float = CONTROL_HZ  #: control (and camera) rate [Hz]: Udacity records at ~15 Hz
    physics_hz: float = PHYSICS_HZ  #: physics sub-step rate [Hz], a multiple of control_hz
    cameras: tuple[str, ...] = ("center", "left", "right")  #: () = state only, no rendering
    image_width: int = IMAGE_WIDTH
    image_height: int = IMAGE_HEIGHT
    scenery: bool = True  #: trees, rocks, barriers... (off: road and terrain only)
    randomize: bool = False  #: domain randomisation of light, fog, tint, camera height, noise
    #: driving conditions of the scene and camera (sim/conditions.py); replaces ``randomize``
    conditions: Conditions | None = None
    vehicle: VehicleParams = field(default_factory=VehicleParams)
    #: who draws the frames: "software" (p3tinydisplay), "egl" (OpenGL through EGL) or "auto"
    #: (EGL where it runs on a GPU, else software); see sim/engine.py
    renderer: str = DEFAULT_RENDERER
    #: render only rows [top, bottom) of each frame, the rest filled with a constant (what a
    #: network that crops its input looks at; sim/cameras.py); None: full frames
    render_rows: tuple[int, int] | None = None
    #: with ``render_rows``: also render the center camera's whole frame for each observation
    #: (:attr:`SimObservation.film_frame`, for a video), while ``images`` keep the strip
    film: bool = False

    def __post_init__(self) -> None:
        substeps = self.physics_hz / self.control_hz
        if self.control_hz <= 0 or abs(substeps - round(substeps)) > 1e-9 or substeps < 1:
            raise ValueError(
                f"physics_hz ({self.physics_hz}) must be a positive multiple of control_hz "
                f"({self.control_hz})"
            )
        unknown = set(self.cameras) - {"center", "left", "right"}
        if unknown:
            raise ValueError(f"unknown camera(s) {sorted(unknown)}; use center, left, right")
        check_renderer(self.renderer)
        if self.render_rows is not None:
            from clonedrive.sim.cameras import check_rows

            object.__setattr__(self, "render_rows", check_rows(self.render_rows,
                                                               self.image_height))


@dataclass(frozen=True)
class SimObservation:
    """Everything measured after a step (see contracts: images are uint8 RGB H x W x 3)."""

    time_s: float
    images: dict
    x_m: float
    y_m: float
    z_m: float
    yaw_rad: float
    pitch_rad: float  #: + = nose up
    roll_rad: float  #: + = right side down
    speed_mph: float
    steering: float
    throttle: float
    brake: float
    s_m: float
    cte_m: float
    heading_error_rad: float
    tyres_on_road: tuple[bool, bool, bool, bool]
    off_road: bool
    laps: int
    distance_m: float
    off_road_events: int
    lap_progress: float  #: fraction of the current lap covered, 0..1
    curvature_per_m: float  #: road curvature here, in the driving direction (+ = left)
    #: The center camera's whole frame where ``images`` hold a strip (``SimConfig.film``).
    film_frame: np.ndarray | None = None

    def state_vector(self) -> np.ndarray:
        """A compact float32 state: speed, steering, CTE, heading error, curvature, on-road."""
        return np.array(
            [self.speed_mph, self.steering, self.cte_m, self.heading_error_rad,
             self.curvature_per_m, float(all(self.tyres_on_road))],
            dtype=np.float32,
        )


@dataclass(frozen=True)
class _Pose:
    """Where the car sits on the track after a step (from one projection of the car's centre
    and its four tyre contact points)."""

    track_s_m: float  #: arc length of the car's centre on the track (the track's direction)
    z_m: float
    pitch_rad: float
    roll_rad: float
    cte_m: float  #: the track's sign convention; the observation flips it when reversed
    tyres_on_road: tuple[bool, bool, bool, bool]
    relative_yaw_rad: float  #: the car's yaw minus the road's heading


class Simulator:
    """A car on a track. Use as a context manager, or call :meth:`close`."""

    def __init__(self, track: Track | str, config: SimConfig | None = None, *,
                 pool: CameraPool | None = None):
        self.track = load_track(track) if isinstance(track, str) else track
        self.config = config or SimConfig()
        #: Where the cameras come from: a :class:`~clonedrive.sim.camera_pool.CameraPool`
        #: shared with the other simulators of a group (one scene for all who look alike), or
        #: None: this simulator builds its own scene.
        self.pool = pool
        self.params = self.config.vehicle
        self._substeps = int(round(self.config.physics_hz / self.config.control_hz))
        self._dt_s = 1.0 / self.config.physics_hz
        self._rig = None
        self._film_rig = None  # the whole-frame center camera of SimConfig.film
        self._state = VehicleState()
        self._obs: SimObservation | None = None  # None until reset()
        self._laps = LapCounter(self.track.length_m)
        self._steps = 0
        self._time_s = 0.0
        self._distance_m = 0.0
        self._controls = Controls()
        self._reverse = False
        self._direction = 1.0
        #: A step begun by :meth:`advance`: the car's new pose, and once rendered its frames
        #: (the cameras' images and the film's whole frame or None, as :meth:`_render` gives).
        self._advanced: _Pose | None = None
        self._advanced_frames: tuple[dict, np.ndarray | None] | None = None

    # ------------------------------------------------------------------ lifecycle
    def __enter__(self) -> Simulator:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Release the rendering engines (if opened), or give the rigs back to the pool."""
        from clonedrive.sim.camera_pool import close_rig

        for rig in (self._rig, self._film_rig):
            if rig is not None and self.pool is not None:
                self.pool.give_back(rig)
            elif rig is not None:
                close_rig(rig)
        self._rig = self._film_rig = None

    def _open_cameras(self, seed: int) -> None:
        self._rig = self._open_rig(self.config, seed)
        if self.config.film and self.config.render_rows is not None:
            whole = replace(self.config, cameras=("center",), render_rows=None, film=False)
            self._film_rig = self._open_rig(whole, seed)

    def _open_rig(self, config: SimConfig, seed: int):
        from clonedrive.sim.camera_pool import build_rig

        if self.pool is not None:
            return self.pool.open(self.track, config, seed)
        return build_rig(self.track, config, seed)

    # ------------------------------------------------------------------ episode
    def reset(self, seed: int | None = None, options: dict | None = None
              ) -> tuple[SimObservation, dict]:
        """Place the car on the track. ``options``: ``s_m`` (start arc length in the driving
        direction), ``offset_m`` (+ = right), ``speed_mph``, ``reverse`` (drive backwards),
        ``yaw_offset_rad``."""
        options = dict(options or {})
        allowed = {"s_m", "offset_m", "speed_mph", "reverse", "yaw_offset_rad"}
        unknown = set(options) - allowed
        if unknown:
            raise ValueError(
                f"unknown reset option(s) {sorted(unknown)}; allowed {sorted(allowed)}")
        if self.config.cameras and self._rig is None:
            self._open_cameras(seed if seed is not None else 0)
        self._reverse = bool(options.get("reverse", False))
        self._direction = -1.0 if self._reverse else 1.0
        self._place(float(options.get("s_m", 0.0)), float(options.get("offset_m", 0.0)),
                    float(options.get("speed_mph", 0.0)),
                    float(options.get("yaw_offset_rad", 0.0)))
        self._steps = 0
        self._time_s = 0.0
        self._distance_m = 0.0
        self._controls = Controls()
        self._advanced = self._advanced_frames = None
        pose = self._pose()
        self._laps.restart(self._s_dir(pose), off_road=not all(pose.tyres_on_road))
        self._obs = self._observation(pose, *self._render(pose))
        return self._obs, {"events": []}

    def step(self, controls: Controls) -> tuple[SimObservation, dict]:
        """One control period: clip the controls, integrate the physics, find the car's pose on
        the track, render the cameras there, count laps and off-road events, observe.

        The same as :meth:`advance`, :meth:`render_advanced` and :meth:`finish_step` in turn:
        the episode runner calls those for all its cars phase by phase (every car's physics,
        then every car's frames, then the rest), which gives each car the same step."""
        self.advance(controls)
        self.render_advanced()
        return self.finish_step()

    def advance(self, controls: Controls) -> None:
        """The first part of :meth:`step`: clip the controls, integrate the physics and find
        the car's new pose on the track. Time and distance advance; the observation stays the
        last one until :meth:`finish_step`."""
        if self._obs is None:
            raise RuntimeError("Simulator.step() before reset(): call reset() to place the car "
                               "on the track first")
        if self._advanced is not None:
            raise RuntimeError("the step is already advanced: call finish_step() first")
        self._integrate(controls.clipped())
        self._advanced = self._pose()

    def render_advanced(self) -> None:
        """The second part of :meth:`step`: render the cameras at the advanced pose."""
        if self._advanced is None:
            raise RuntimeError("nothing to render: call advance() first")
        if self._advanced_frames is None:
            self._advanced_frames = self._render(self._advanced)

    def finish_step(self) -> tuple[SimObservation, dict]:
        """The last part of :meth:`step` (rendering first if :meth:`render_advanced` was not
        called): count laps and off-road events, observe. Returns what :meth:`step` returns."""
        self.render_advanced()
        pose, (images, film_frame) = self._advanced, self._advanced_frames
        self._advanced = self._advanced_frames = None
        lap = self._count(pose)
        self._obs = self._observation(pose, images, film_frame)
        events = [lap.event] if lap.event is not None else []
        return self._obs, {"events": events, "lap_completed": lap.lap_completed}

    def intervene(self, speed_mph: float) -> SimObservation:
        """Put the car back on the centreline where it is, heading along the road, at
        ``speed_mph``; time, distance and lap progress carry on. (The episode runner,
        :mod:`clonedrive.episode`, decides when and at what speed: DESIGN.md's intervention.)"""
        if self._obs is None:
            raise RuntimeError("Simulator.intervene() before reset(): call reset() first")
        if self._advanced is not None:
            raise RuntimeError("Simulator.intervene() in the middle of a step: finish it first")
        self._place(self._obs.s_m, 0.0, speed_mph, 0.0)
        pose = self._pose()
        self._laps.placed(self._s_dir(pose), off_road=not all(pose.tyres_on_road))
        self._obs = self._observation(pose, *self._render(pose))
        return self._obs

    # ------------------------------------------------------------------ the steps of a step
    def _track_s(self, s_m: float) -> float:
        """Arc length on the track for arc length ``s_m`` measured in the driving direction."""
        return float(self.track.wrap(self._direction * s_m))

    def _s_dir(self, pose: _Pose) -> float:
        """The pose's arc length measured in the driving direction."""
        return float(self.track.wrap(self._direction * pose.track_s_m))

    def _place(self, s_m: float, offset_m: float, speed_mph: float, yaw_offset_rad: float) -> None:
        track_s = self._track_s(s_m)
        x, y, _ = self.track.offset_point(track_s, self._direction * offset_m)
        yaw = float(self.track.heading_at(track_s)) + (math.pi if self._reverse else 0.0)
        self._state = VehicleState(x_m=float(x), y_m=float(y),
                                   yaw_rad=float(wrap_angle(yaw + yaw_offset_rad)),
                                   v_x_mps=speed_mph * MPH_TO_MPS)

    def _integrate(self, controls: Controls) -> None:
        """Physics sub-steps for one control period; time and distance advance."""
        state = integrate(self._state, controls, self._dt_s, self.params, self._road_contact(),
                          self._substeps)
        self._distance_m += math.hypot(state.x_m - self._state.x_m, state.y_m - self._state.y_m)
        self._state = state
        self._controls = controls
        self._steps += 1
        self._time_s = self._steps / self.config.control_hz  # exact, no drift from summing

    def _road_contact(self) -> RoadContact:
        obs = self._obs
        grade = math.tan(obs.pitch_rad)
        flags = obs.tyres_on_road
        return RoadContact(grade=grade, front_on_road=0.5 * (flags[0] + flags[1]),
                           rear_on_road=0.5 * (flags[2] + flags[3]))

    def _pose(self) -> _Pose:
        state = self._state
        points = np.array([(state.x_m, state.y_m), *tyre_positions(state, self.params)])
        proj = self.track.project(points)
        on_road = np.abs(proj.cte_m[1:]) <= proj.half_width_m[1:]
        track_s = float(proj.s_m[0])
        grade = float(self.track.grade(track_s))
        relative = state.yaw_rad - float(self.track.heading_at(track_s))
        return _Pose(
            track_s_m=track_s,
            z_m=float(proj.z_m[0]),
            pitch_rad=math.atan(grade * math.cos(relative)),
            roll_rad=math.atan(grade * math.sin(relative)),  # right lower when the road rises left
            cte_m=float(proj.cte_m[0]),
            tyres_on_road=tuple(bool(v) for v in on_road),
            relative_yaw_rad=relative,
        )

    def _render(self, pose: _Pose) -> tuple[dict, np.ndarray | None]:
        """The cameras' frames at ``pose``, and the film's whole frame (or None)."""
        if self._rig is None:
            return {}, None
        state = self._state
        where = (state.x_m, state.y_m, pose.z_m, state.yaw_rad, pose.pitch_rad, pose.roll_rad)
        images = self._rig.render(*where)
        film_frame = None if self._film_rig is None else self._film_rig.render(*where)["center"]
        return images, film_frame

    def _count(self, pose: _Pose):
        state = self._state
        return self._laps.update(s_m=self._s_dir(pose), off_road=not all(pose.tyres_on_road),
                                 time_s=self._time_s, x_m=state.x_m, y_m=state.y_m,
                                 cte_m=self._direction * pose.cte_m)

    def _observation(self, pose: _Pose, images: dict,
                     film_frame: np.ndarray | None) -> SimObservation:
        state = self._state
        direction = self._direction
        laps = self._laps
        return SimObservation(
            time_s=self._time_s,
            images=images,
            x_m=state.x_m,
            y_m=state.y_m,
            z_m=pose.z_m,
            yaw_rad=state.yaw_rad,
            pitch_rad=pose.pitch_rad,
            roll_rad=pose.roll_rad,
            speed_mph=state.v_x_mps / MPH_TO_MPS,
            steering=self._controls.steering,
            throttle=self._controls.throttle,
            brake=self._controls.brake,
            s_m=self._s_dir(pose),
            cte_m=direction * pose.cte_m,
            heading_error_rad=float(wrap_angle(pose.relative_yaw_rad
                                               + (math.pi if self._reverse else 0.0))),
            tyres_on_road=pose.tyres_on_road,
            off_road=not all(pose.tyres_on_road),
            laps=laps.laps,
            distance_m=self._distance_m,
            off_road_events=len(laps.events),
            lap_progress=laps.lap_progress,
            curvature_per_m=direction * float(self.track.curvature(pose.track_s_m)),
            film_frame=film_frame,
        )

    # ------------------------------------------------------------------ read-only state
    @property
    def observation(self) -> SimObservation:
        if self._obs is None:
            raise RuntimeError("call reset() first")
        return self._obs

    @property
    def events(self) -> list[OffRoadEvent]:
        """This episode's off-road events, in order."""
        return list(self._laps.events)

    @property
    def laps_started(self) -> int:
        """Index of the lap being driven (laps attempted so far, counting completed ones)."""
        return self._laps.lap_index
