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

Run: python benchmarks/replay.py [--rows 200] [--model best=runs/demo/train/model.keras]
     [--replay-log DIR ...] [--trust-model]
Ends with one JSON line: {"side_view_error_ratio", "side_view_error_synthesised",
"side_view_error_unshifted", "side_view_error_ratio_unsmoothed",
"side_view_error_ratio_default_rig", "rows_compared", "rows_better", "fitted_left_x_m",
"fitted_right_x_m", "fitted_horizon_row", "replay": {label: {log: {autonomy_pct,
interventions, interventions_per_km, distance_m, mean_abs_offset_m, jitter_per_s}}}}.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from clonedrive.data.driving_log import read_driving_log
from clonedrive.replay.episode import frame_images
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
    from clonedrive.drivers.network import load_policy
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--log", type=Path, default=THREE_CAMERA_LOG,
                        help="three-camera log for the side-view comparison")
    parser.add_argument("--rows", type=int, default=200)
    parser.add_argument("--model", action="append", default=[], metavar="LABEL=PATH")
    parser.add_argument("--replay-log", action="append", type=Path, default=None)
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
    print(json.dumps(result))


if __name__ == "__main__":
    main()
