"""Record the expert's driving as a Udacity-format log: ``driving_log.csv`` + ``IMG/`` + config.

``record(config, out_dir)`` drives the :class:`~clonedrive.drivers.expert.ExpertPolicy` around a
track in the simulator with its three cameras and writes one row per control step (15 Hz) in
exactly the Udacity simulator's format (UDACITY.md), through
:class:`~clonedrive.data.row_sink.RowSink` and its
:class:`~clonedrive.data.log_writer.DrivingLogWriter`:

- ``IMG/center_|left_|right_YYYY_MM_DD_HH_MM_SS_mmm.jpg``: 320x160 RGB JPEGs (quality 75 by
  default, as Unity's ``EncodeToJPG``). The timestamps follow **simulated** time from the
  recording's start, so names are unique and 1/15 s apart however fast the recording runs. The
  start is the wall-clock local time (whole milliseconds) when recording begins, or
  ``start_time`` when given (reproducible names).
- Each row: the three image paths (absolute by default, ``IMG/<name>`` with ``relative_paths``),
  the expert's **clean** steering label (not the noisy steering it applied), the applied throttle
  and brake in [0, 1], and the speed in mph at the moment the images were taken.
- ``target_speed.csv`` (:mod:`clonedrive.data.speed_labels`): per row, the expert's speed label
  (the speed it would aim for there with no set-speed cap), the target a network's speed head
  learns; written before the row it labels. Udacity's tools never open it.
- ``style="turns"`` writes only the rows in curves; the others are counted as skipped.
- ``config.json``: the :class:`RecordConfig` plus the track's version, the clonedrive version
  and a list of the recording sessions, written atomically.

**Nothing is lost.** Images are JPEG-encoded and written by a background thread while the next
frame renders; each image is written to a temporary name and renamed into place, and a row is
appended (one ``write`` call) only once its three images are in place, in step order. A recorder
killed at any moment therefore leaves a log whose every row's images exist and decode (at most a
few orphan images or ``.tmp`` files, which a later append removes). Process death never loses
data that was written, since it stays in the OS page cache; against power loss the CSV is
``fsync``-ed every ``fsync_every_rows`` rows and at the end, and images are not fsynced one by
one (that would halve the speed), so after a power cut the last rows may point to images the
reader reports as missing; it skips and counts them.

**An existing folder is appended to**, not overwritten: the new rows' timestamps continue after
the last image already in the log (or at the current time, if later), so names stay unique and
ordered, and ``config.json`` gains a session. Use a new folder for a separate data set.

**One recorder per folder.** A recording holds the folder's lock file
(:mod:`clonedrive.data.recording_lock`) from before it reads the folder until its last row is
written; a second recorder started meanwhile is refused with a message naming the first, and the
lock a killed recorder leaves behind is recognised as stale and taken over.

The driving loop is the episode runner's (:mod:`clonedrive.episode`), with the expert as the
driver: recording stops after ``laps`` laps in the driving direction (or ``seconds`` of simulated
driving, if given, whichever comes first), or earlier (with ``stopped="off_road"``) once the
expert has left the road ``max_off_road_events`` times, or at the runner's time limit. An
off-road event is counted but not intervened: the expert steers back by itself, and those
recovery rows are recorded with its clean labels.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import asdict, dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np

from clonedrive.base.config import config_to_dict
from clonedrive.base.paths import check_output_folder
from clonedrive.base.udacity_spec import JPEG_QUALITY
from clonedrive.data.driving_log import STEERING_HISTOGRAM_BINS
from clonedrive.data.log_folder import check_start_time, prepare_log_folder, write_session_config
from clonedrive.data.recording_lock import RecordingLock
from clonedrive.data.row_sink import RowSink
from clonedrive.drivers.expert import STYLES, ExpertConfig, ExpertPolicy
from clonedrive.episode.rules import EpisodeRules, Stop
from clonedrive.sim.engine import DEFAULT_RENDERER, check_renderer
from clonedrive.world.vehicle import check_set_speed


@dataclass(frozen=True)
class RecordConfig:
    """What to record. Saved as ``config.json`` next to the log."""

    track: str = "lake"  #: built-in name, gen:<seed> or a track .json path
    style: str = "center"  #: center, left, right, weave or turns (see drivers/expert.py)
    laps: int = 1  #: laps to drive in the driving direction
    seconds: float | None = None  #: also stop after this much simulated time [s] (None: no limit)
    speed_mph: float = 15.0  #: set speed: a maximum, the expert slows for curves
    reverse: bool = False  #: drive the track backwards
    noise: float = 0.0  #: steering-noise std applied to the car; labels stay clean
    seed: int = 0  #: seeds the noise, the weave phase and the scene
    header: bool = False  #: write the header line (the simulator writes none)
    relative_paths: bool = False  #: IMG/<name> instead of absolute paths
    offset_fraction: float = 0.6  #: left/right: fraction of the usable half-width off centre
    jpeg_quality: int = JPEG_QUALITY  #: JPEG quality 1-100
    max_off_road_events: int = 3  #: stop early once the expert has left the road this often
    scenery: bool = True  #: trees, rocks... (False: road and terrain only)
    #: the look (sim/conditions.py RECORDING_LOOKS): a condition family such as "udacity"
    #: drawn from ``seed``, or "randomized" (domain randomisation); None: the theme's own
    look: str | None = None
    start_time: str | None = None  #: ISO time of the first image name; None = now (local time)
    fsync_every_rows: int = 15  #: fsync the CSV this often (and at the end); 1 = every row
    turn_curvature_per_m: float | None = None  #: turns style: record where |curvature| > this
    renderer: str = DEFAULT_RENDERER  #: who draws the frames (sim/engine.py)

    def __post_init__(self) -> None:
        if self.style not in STYLES:
            raise ValueError(f"style {self.style!r} is not one of {', '.join(STYLES)}")
        if self.laps < 1:
            raise ValueError(f"laps must be at least 1, got {self.laps}")
        check_set_speed(self.speed_mph)
        if not 0.0 <= self.noise <= 1.0:
            raise ValueError(f"noise must be in [0, 1] (steering units), got {self.noise}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be in [1, 100], got {self.jpeg_quality}")
        if self.seconds is not None and not (math.isfinite(self.seconds) and self.seconds > 0):
            raise ValueError(f"seconds must be a positive number of seconds, got {self.seconds}")
        if self.max_off_road_events < 1 or self.fsync_every_rows < 1:
            raise ValueError("max_off_road_events and fsync_every_rows must be at least 1")
        check_renderer(self.renderer)
        if self.start_time is not None:
            check_start_time(datetime.fromisoformat(self.start_time))  # ValueError naming it
        self.expert_config()  # the expert's own checks (offset fraction, ...)
        self.conditions()  # an unknown look is named
        self.episode_rules()

    def episode_rules(self) -> EpisodeRules:
        """The runner's rules for this recording: the laps, the cap on seconds, the off-road
        limit; off-road events are counted, not intervened (the expert recovers)."""
        return EpisodeRules(laps=self.laps, set_speed_mph=self.speed_mph, off_road="continue",
                            max_off_road_events=self.max_off_road_events,
                            max_seconds=self.seconds)

    def conditions(self):
        """The :class:`~clonedrive.sim.conditions.Conditions` of ``look`` drawn from ``seed``,
        or None (the theme's own look, or domain randomisation: :meth:`randomized`)."""
        from clonedrive.sim.conditions import FAMILIES, check_recording_look

        check_recording_look(self.look)
        if self.look is None or self.randomized:
            return None
        return FAMILIES[self.look].sample(self.seed)

    @property
    def randomized(self) -> bool:
        """Whether the look is domain randomisation (``look = "randomized"``)."""
        from clonedrive.sim.conditions import RANDOMIZED_LOOK

        return self.look == RANDOMIZED_LOOK

    def expert_config(self) -> ExpertConfig:
        options = {}
        if self.turn_curvature_per_m is not None:
            options["turn_curvature_per_m"] = self.turn_curvature_per_m
        return ExpertConfig(style=self.style, speed_mph=self.speed_mph, reverse=self.reverse,
                            noise=self.noise, offset_fraction=self.offset_fraction, **options)


@dataclass
class RecordSummary:
    """What a recording produced."""

    out_dir: str
    rows: int  #: rows written by this recording
    total_rows: int  #: rows in the log afterwards (more when appending)
    off_road_events: int
    laps: int  #: laps driven in the driving direction
    clean_laps: int  #: of those, laps without an off-road event
    sim_seconds: float  #: simulated time driven
    wall_seconds: float  #: driving and writing, from the first step until every row is written
    setup_seconds: float  #: building the scene before the first step
    samples_per_s: float  #: rows written per wall-clock second of driving (setup excluded)
    distance_m: float
    skipped_samples: int  #: steps not recorded (``turns``: outside curves)
    stopped: str  #: "laps", "seconds", "off_road", "time_limit" or "interrupted"
    appended: bool  #: the folder already held a log
    first_image: str | None
    last_image: str | None
    steering_histogram: dict = field(default_factory=dict)  #: {"edges": [...], "counts": [...]}
    message: str = ""

    def to_dict(self) -> dict:
        return asdict(self)


def record(config: RecordConfig, out_dir: str | os.PathLike, *, progress: bool = True
           ) -> RecordSummary:
    """Drive the expert and record a Udacity-format log into ``out_dir`` (appending if one is
    there). ``progress``: show a tqdm bar (stderr) by lap progress.

    Only one recorder writes into a folder at a time: a second one raises
    :class:`~clonedrive.data.recording_lock.RecordingLockedError` before touching anything,
    and an ``out_dir`` that is a file raises ``ValueError``."""
    out = check_output_folder(Path(out_dir).absolute())
    with RecordingLock(out):
        return _record(config, out, progress=progress)


def _record(config: RecordConfig, out_dir: Path, *, progress: bool) -> RecordSummary:
    from clonedrive import __version__
    from clonedrive.episode.drivers import ExpertDriver
    from clonedrive.episode.runner import Episode, PerCar, Runner, Step
    from clonedrive.sim.simulator import SimConfig, Simulator
    from clonedrive.world.catalog import load_track

    out = Path(out_dir).absolute()
    track = load_track(config.track)
    existing_rows, start = prepare_log_folder(out, config.start_time)
    session = {"started": start.isoformat(timespec="milliseconds"), "rows": None,
               **config_to_dict(config)}
    write_session_config(out, config, track, __version__, session)

    rng = np.random.default_rng(config.seed)
    expert = ExpertPolicy(track, config.expert_config(), rng)
    sim_config = SimConfig(scenery=config.scenery, randomize=config.randomized,
                           conditions=config.conditions(), renderer=config.renderer)
    steering: list[float] = []
    skipped = 0
    first_name = last_name = None
    setup_start = time.perf_counter()
    with Simulator(track, sim_config) as sim, \
            RowSink(out, start, header=config.header, relative_paths=config.relative_paths,
                    jpeg_quality=config.jpeg_quality,
                    fsync_every_rows=config.fsync_every_rows) as sink:
        # The expert recovers by itself: an off-road event is counted, not intervened.
        episode = Episode(sim, config.episode_rules(), track=config.track, seed=config.seed,
                          options={"reverse": config.reverse}, trace=False)
        runner = Runner([episode], PerCar([ExpertDriver(expert)]))
        runner.reset()
        wall_start = time.perf_counter()
        bar = _progress_bar(config.laps, progress)

        def on_step(step: Step) -> None:
            nonlocal skipped, first_name, last_name
            decision = step.decision
            if decision.record:
                names = sink.submit(step.seen, decision.label, decision.controls,
                                    target_speed_mph=decision.detail.label_speed_mph)
                steering.append(decision.label)
                first_name = first_name or names[0]
                last_name = names[0]
            else:
                skipped += 1
            if bar is not None:
                obs = step.observed
                bar.update(episode.laps_started + obs.lap_progress - bar.n)
                bar.set_postfix(rows=len(steering), off_road=obs.off_road_events, refresh=False)

        try:
            runner.run(on_step)
        except KeyboardInterrupt:
            episode.stop(Stop.INTERRUPTED)
        finally:
            if bar is not None:
                bar.close()
        sink.close()
        rows = sink.rows_written
        obs = episode.observation
        stopped = str(episode.stopped)
        laps_started = episode.laps_started
    wall = time.perf_counter() - wall_start
    setup = wall_start - setup_start
    time_limit_s = episode.time_limit_s

    session["rows"] = rows
    write_session_config(out, config, track, __version__, session)
    counts, edges = np.histogram(np.asarray(steering[:rows]), bins=STEERING_HISTOGRAM_BINS,
                                 range=(-1.0, 1.0))
    messages = {
        "laps": f"recorded {config.laps} lap(s)",
        "seconds": f"recorded {config.seconds:g} s of driving" if config.seconds else "",
        "off_road": f"stopped early: the expert left the road {obs.off_road_events} times "
                    f"(limit {config.max_off_road_events}); try a lower --speed or --noise",
        "time_limit": f"stopped early: {time_limit_s:.0f} s of driving did not finish "
                      f"{config.laps} lap(s)",
        "interrupted": "interrupted; every row written so far is complete",
    }
    return RecordSummary(
        out_dir=str(out),
        rows=rows,
        total_rows=existing_rows + rows,
        off_road_events=obs.off_road_events,
        laps=min(laps_started, config.laps),
        clean_laps=obs.laps,
        sim_seconds=obs.time_s,
        wall_seconds=wall,
        setup_seconds=setup,
        samples_per_s=rows / wall if wall > 0 else 0.0,
        distance_m=obs.distance_m,
        skipped_samples=skipped,
        stopped=stopped,
        appended=existing_rows > 0,
        first_image=first_name,
        last_image=last_name,
        steering_histogram={"edges": [float(e) for e in edges],
                            "counts": [int(c) for c in counts]},
        message=messages[stopped],
    )


def _progress_bar(laps: int, enabled: bool):
    if not enabled:
        return None
    from clonedrive.base.progress import progress_bar

    return progress_bar(
        total=laps, desc="recording", unit="lap",
        bar_format="{l_bar}{bar}| {n:.2f}/{total} laps [{elapsed}<{remaining}{postfix}]")
