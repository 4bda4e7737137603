"""Viewpoint synthesis against the real side cameras, and replay figures of models (issue 32).

1. ``side_view_error_ratio``: on a three-camera Udacity log (default: the real
   ``lake_rikki_3cam`` in ../shared/realdata), the left and right views synthesised from the
   centre image alone, at the side offsets fitted from the log, against the real side images:
   mean |synthesised - real| over the road region (0-255, both images smoothed by
   ``clonedrive.replay.view.COMPARE_SMOOTHING_PX``), divided by the same for the unshifted
   centre image. Also without the smoothing, and at the default (unfitted) offsets.
2. With ``--model LABEL=PATH`` (repeatable): ``clonedrive replay``'s autonomy, interventions per
   km, mean |offset| and jitter of each model on each replay log (default: the real lake and
   mountain logs), beside the always-0 baseline (``always_zero``).
3. With ``--sim-model LABEL=PATH`` (repeatable): ``sim_rank_correlation``, the Spearman rank
   correlation between replay and true closed-loop interventions per km in clonedrive, over
   every model and ``--sim-condition TRACK@MPH`` (a lap recorded with all three cameras, then
   replayed; the same track and speed driven by ``clonedrive evaluate``); the same for the
   replay's mean |offset| against the true mean |cross-track error|
   (``sim_rank_correlation_offset``), and the mean |difference| in interventions per km. Over
   models as well (``sim_rank_correlation_models``, ``..._models_autonomy``): each model's
   interventions, distance and time summed over the conditions, ranked by interventions per
   km and by PilotNet's autonomy, in replay against true closed loop.

Run: python benchmarks/replay.py [--rows 200] [--model best=runs/demo/train/model.keras]
     [--replay-log DIR ...] [--sim-model LABEL=PATH ... --sim-condition lake@15 ...
     --sim-max-offset default|road --sim-vehicle-model kinematic|dynamic] [--trust-model]
Ends with one JSON line: {"side_view_error_ratio", "side_view_error_synthesised",
"side_view_error_unshifted", "side_view_error_ratio_unsmoothed",
"side_view_error_ratio_default_rig", "rows_compared", "rows_better", "fitted_left_x_m",
"fitted_right_x_m", "fitted_horizon_row", "replay": {label: {log: {autonomy_pct,
interventions, interventions_per_km, distance_m, mean_abs_offset_m, jitter_per_s}}},
and with --sim-model "sim_rank_correlation", "sim_rank_correlation_offset",
"sim_interventions_per_km_mean_abs_difference", "sim_rank_correlation_models",
"sim_rank_correlation_models_autonomy", "sim_vehicle_model", "sim_models", "sim_pairs"}.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from clonedrive.data.driving_log import read_driving_log
from clonedrive.replay.episode import frame_images
from clonedrive.replay.motion import VEHICLE_MODELS
from clonedrive.replay.view import (
    CALIBRATION_FRAMES,
    Rig,
    calibrate,
    road_mask,
    synthesise,
    view_error,
)

REALDATA = Path(__file__).resolve().parents[2] / "shared" / "realdata"
THREE_CAMERA_LOG = REALDATA / "lake_rikki_3cam"
REPLAY_LOGS = (REALDATA / "lake_rikki_center", REALDATA / "mountain_tuong_center")
ZERO_LABEL = "always_zero"  #: the baseline's label in the replay figures
TOTAL_KEYS = ("interventions", "distance_m", "elapsed_s")  #: summed per model over conditions
REPLAY_KEYS = ("autonomy_pct", "interventions", "interventions_per_km", "distance_m",
               "mean_abs_offset_m", "jitter_per_s")


def side_view_figures(log: Path, count: int) -> dict:
    """The side-view comparison over ``count`` evenly spaced rows of ``log``."""
    rows = read_driving_log(log).rows
    picks = np.linspace(0, len(rows) - 1, min(count, len(rows))).round().astype(int)
    frames = [frame_images(rows[pick]) for pick in picks]
    fitted = calibrate(Rig(), [frames[i] for i in
                               np.linspace(0, len(frames) - 1, CALIBRATION_FRAMES).astype(int)])
    figures = {}
    for name, rig, smoothing in (("fitted", fitted, None), ("unsmoothed", fitted, 1),
                                 ("default", Rig(), None)):
        errors = np.zeros((len(frames), 2, 2))  # frame, side, (synthesised, unshifted)
        for side, camera in enumerate(("left", "right")):
            where = rig.source_x(camera)
            mask = road_mask(rig, where)
            options = {} if smoothing is None else {"smoothing_px": smoothing}
            for index, frame in enumerate(frames):
                view = synthesise({"center": frame["center"]}, rig, where, 0.0)
                errors[index, side] = (view_error(view, frame[camera], mask, **options),
                                       view_error(frame["center"], frame[camera], mask,
                                                  **options))
        figures[name] = errors
    main = figures["fitted"]
    synthesised, unshifted = float(main[..., 0].mean()), float(main[..., 1].mean())
    ratio = {name: round(float(errors[..., 0].mean() / errors[..., 1].mean()), 4)
             for name, errors in figures.items()}
    return {
        "side_view_error_ratio": ratio["fitted"],
        "side_view_error_synthesised": round(synthesised, 3),
        "side_view_error_unshifted": round(unshifted, 3),
        "side_view_error_ratio_unsmoothed": ratio["unsmoothed"],
        "side_view_error_ratio_default_rig": ratio["default"],
        "rows_compared": len(frames),
        "rows_better": int((main[..., 0] < main[..., 1]).all(axis=1).sum()),
        "fitted_left_x_m": fitted.left_x_m,
        "fitted_right_x_m": fitted.right_x_m,
        "fitted_horizon_row": fitted.horizon_row,
    }


class AlwaysZero:
    """The baseline that needs no model: it never steers."""

    def reset(self) -> None:
        pass

    def act(self, image: np.ndarray, speed_mph: float) -> tuple[float, float]:
        return 0.0, 0.0


def replay_figures(models: list[str], logs: list[Path], trust: bool) -> dict:
    from clonedrive.drivers.policy import load_policy
    from clonedrive.replay.output import replay

    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="replay-") as scratch:
        for entry in [*models, ZERO_LABEL]:
            label, _, path = entry.partition("=")
            if not path:
                label, path = Path(entry).stem, entry
            policy = AlwaysZero() if entry == ZERO_LABEL else load_policy(path, trust=trust)
            results[label] = {}
            for log in logs:
                started = time.perf_counter()
                report = replay(policy, [log], Path(scratch) / label / log.name,
                                model_path=path)
                figures = {key: report["totals"][key] for key in REPLAY_KEYS}
                results[label][log.name] = figures
                print(f"{label} on {log.name}: {figures} "
                      f"({time.perf_counter() - started:.0f} s)")
    return results


def road_offset_m(track_name: str) -> float:
    """The offset from the centre line at which a tyre leaves the narrowest stretch of the
    track: where ``evaluate`` counts an intervention (``--sim-max-offset road``)."""
    from clonedrive.world.catalog import load_track
    from clonedrive.world.vehicle import VehicleParams

    track = load_track(track_name)
    return round(0.5 * float(np.min(track.width)) - 0.5 * VehicleParams().track_width_m, 3)


def sim_comparison(models: list[str], conditions: list[str], trust: bool,
                   max_offset: str = "default", vehicle_model: str | None = None) -> dict:
    """Each model replayed on a clonedrive-recorded lap (three cameras) and driven in true closed
    loop on the same track at the same speed: rank correlations between the two over all
    (model, condition) pairs, and the mean |difference| of interventions per km.
    ``max_offset``: ``default`` (the replay's 1 m from the expert's path) or ``road`` (where a
    tyre would leave the track's narrowest stretch, the true loop's intervention). Also over
    models: each model's interventions and elapsed time summed over the conditions, ranked by
    interventions per km and by autonomy."""

    from clonedrive.drivers.policy import load_policy
    from clonedrive.replay.episode import ReplayConfig
    from clonedrive.replay.output import replay

    base = ReplayConfig(**({"vehicle_model": vehicle_model} if vehicle_model else {}))
    pairs = []
    with tempfile.TemporaryDirectory(prefix="replay-sim-") as scratch:
        for condition in conditions:
            track, _, speed = condition.partition("@")
            lap = Path(scratch) / f"{track}_{speed}"
            _cli("record", "--track", track, "--laps", "1", "--speed", speed, "--out", str(lap))
            config = (replace(base, max_offset_m=road_offset_m(track)) if max_offset == "road"
                      else base)
            for entry in models:
                label, _, path = entry.partition("=")
                report = replay(load_policy(path, trust=trust), [lap],
                                Path(scratch) / "replay" / label / lap.name, config)["totals"]
                extra = ["--trust-model"] if trust else []
                run = json.loads(_cli("evaluate", path, "--track", track, "--speed", speed,
                                      "--laps", "1", "--json", *extra,
                                      "--out", str(Path(scratch) / "eval" / label / lap.name))
                                 )["runs"][0]
                true_per_km = run["interventions"] / (run["distance_m"] / 1000.0)
                pairs.append({"model": label, "condition": condition,
                              "replay_max_offset_m": config.max_offset_m,
                              "replay_interventions_per_km": report["interventions_per_km"],
                              "sim_interventions_per_km": round(true_per_km, 3),
                              "replay_mean_abs_offset_m": report["mean_abs_offset_m"],
                              "sim_mean_abs_cte_m": run["mean_abs_cte_m"],
                              **{f"replay_{key}": report[key] for key in TOTAL_KEYS},
                              **{f"sim_{key}": run[key] for key in TOTAL_KEYS}})
                print(pairs[-1])
    per_model = model_totals(pairs)
    return {
        "sim_rank_correlation": rank(pairs, "replay_interventions_per_km",
                                     "sim_interventions_per_km"),
        "sim_rank_correlation_offset": rank(pairs, "replay_mean_abs_offset_m",
                                            "sim_mean_abs_cte_m"),
        "sim_interventions_per_km_mean_abs_difference": round(float(np.mean(
            [abs(pair["replay_interventions_per_km"] - pair["sim_interventions_per_km"])
             for pair in pairs])), 3),
        "sim_rank_correlation_models": rank(per_model, "replay_interventions_per_km",
                                            "sim_interventions_per_km"),
        "sim_rank_correlation_models_autonomy": rank(per_model, "replay_autonomy_pct",
                                                     "sim_autonomy_pct"),
        "sim_vehicle_model": base.vehicle_model,
        "sim_models": per_model,
        "sim_pairs": pairs,
    }


def rank(rows: list[dict], first: str, second: str) -> float:
    """Spearman's rank correlation of two keys over ``rows``."""
    from scipy.stats import spearmanr

    value = spearmanr([row[first] for row in rows], [row[second] for row in rows])[0]
    return round(float(value), 4)


def model_totals(pairs: list[dict]) -> list[dict]:
    """Per model, over its conditions: interventions per km and PilotNet's autonomy (6 s per
    intervention, floored at 0) from the summed interventions, distance and time, in replay
    and in true closed loop."""
    from clonedrive.replay.episode import ReplayConfig, autonomy

    penalty_s = ReplayConfig().intervention_penalty_s
    rows = []
    for label in dict.fromkeys(pair["model"] for pair in pairs):
        mine = [pair for pair in pairs if pair["model"] == label]
        row = {"model": label, "conditions": len(mine)}
        for side in ("replay", "sim"):
            count, metres, seconds = (sum(pair[f"{side}_{key}"] for pair in mine)
                                      for key in TOTAL_KEYS)
            row[f"{side}_interventions_per_km"] = round(count / (metres / 1000.0), 3)
            row[f"{side}_autonomy_pct"] = autonomy(count, seconds, penalty_s)
        rows.append(row)
    return rows


def _cli(*arguments: str) -> str:
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "clonedrive", *arguments], check=True,
                          capture_output=True, text=True)
    return done.stdout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--log", type=Path, default=THREE_CAMERA_LOG,
                        help="three-camera log for the side-view comparison")
    parser.add_argument("--rows", type=int, default=200)
    parser.add_argument("--model", action="append", default=[], metavar="LABEL=PATH")
    parser.add_argument("--replay-log", action="append", type=Path, default=None)
    parser.add_argument("--sim-model", action="append", default=[], metavar="LABEL=PATH",
                        help="replay against true closed loop in clonedrive (repeatable)")
    parser.add_argument("--sim-condition", action="append", default=None, metavar="TRACK@MPH",
                        help="track and speed of the sim comparison (default: lake@15)")
    parser.add_argument("--sim-max-offset", choices=("default", "road"), default="default",
                        help="the replay's intervention in the sim comparison: 1 m from the "
                             "expert's path (default), or where a tyre leaves the road (road)")
    parser.add_argument("--sim-vehicle-model", choices=VEHICLE_MODELS, default=None,
                        help="the replay's vehicle model in the sim comparison (default: "
                             "clonedrive replay's)")
    parser.add_argument("--trust-model", action="store_true")
    args = parser.parse_args()

    started = time.perf_counter()
    result = side_view_figures(args.log, args.rows)
    print(f"side views on {args.log.name}, {result['rows_compared']} rows: synthesised "
          f"{result['side_view_error_synthesised']:.2f} vs unshifted "
          f"{result['side_view_error_unshifted']:.2f} -> ratio "
          f"{result['side_view_error_ratio']:.3f} (unsmoothed "
          f"{result['side_view_error_ratio_unsmoothed']:.3f}, default rig "
          f"{result['side_view_error_ratio_default_rig']:.3f}); better on "
          f"{result['rows_better']} of {result['rows_compared']} rows; fitted side cameras "
          f"{result['fitted_left_x_m']:+.2f} / {result['fitted_right_x_m']:+.2f} m, horizon "
          f"row {result['fitted_horizon_row']} "
          f"({time.perf_counter() - started:.0f} s)")
    logs = args.replay_log or list(REPLAY_LOGS)
    result["replay"] = replay_figures(args.model, logs, args.trust_model) if args.model else {}
    if args.sim_model:
        result.update(sim_comparison(args.sim_model, args.sim_condition or ["lake@15"],
                                     args.trust_model, args.sim_max_offset,
                                     args.sim_vehicle_model))
    print(json.dumps(result))


if __name__ == "__main__":
    main()
