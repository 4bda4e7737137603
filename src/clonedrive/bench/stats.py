"""Uncertainty for benchmark figures: bootstrap confidence intervals over episodes (and over a
method's models, hierarchically), and paired comparisons of two methods on the same episodes.

- :func:`bootstrap_ci`: the 95 % percentile interval of a figure over episodes resampled with
  replacement.
- :func:`hierarchical_ci`: for a method trained with several seeds, resample the models, then
  each drawn model's episodes: the interval holds both the seed spread and the episode spread.
- :func:`paired_comparison`: two methods on the episodes both drove (matched by the suite's
  episode key), the mean difference per episode with its bootstrap interval, a two-sided
  sign-flip permutation p-value, a plain sentence, and how many episodes a difference of the
  observed size would need to be detected (paired normal approximation, 5 % level, 80 % power).

Every draw comes from a ``numpy.random.Generator`` seeded by the caller: the same bench.json
gives the same intervals and p-values.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np

#: Resamples per interval or permutation test.
RESAMPLES = 2000
#: Two-sided confidence level of every interval.
CONFIDENCE = 0.95
#: Significance level of the comparison's sentence.
ALPHA = 0.05
#: Power the "episodes needed" estimate is for.
POWER = 0.8
#: Seed of the generator when the caller gives none.
DEFAULT_SEED = 0


def bootstrap_ci(values: Sequence[float], *, statistic: Callable = np.mean,
                 resamples: int = RESAMPLES, seed: int = DEFAULT_SEED) -> dict:
    """``{"value", "low", "high", "n"}``: the statistic of ``values`` and its percentile
    interval over resampled episodes (None for no values; one value has no spread)."""
    data = np.asarray([v for v in values if v is not None], dtype=float)
    if data.size == 0:
        return {"value": None, "low": None, "high": None, "n": 0}
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, data.size, size=(resamples, data.size))
    spread = statistic(data[draws], axis=1)
    return _interval(float(statistic(data)), spread, data.size)


def ratio_ci(numerators: Sequence[float], denominators: Sequence[float], *,
             resamples: int = RESAMPLES, seed: int = DEFAULT_SEED) -> dict:
    """A pooled ratio (sum of numerators / sum of denominators, e.g. interventions per km) and
    its interval over resampled episodes (None where the denominators sum to 0)."""
    top = np.asarray(numerators, dtype=float)
    bottom = np.asarray(denominators, dtype=float)
    if top.size == 0 or bottom.sum() <= 0:
        return {"value": None, "low": None, "high": None, "n": int(top.size)}
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, top.size, size=(resamples, top.size))
    sums = bottom[draws].sum(axis=1)
    spread = np.where(sums > 0, top[draws].sum(axis=1) / np.where(sums > 0, sums, 1.0), np.nan)
    spread = spread[np.isfinite(spread)]
    return _interval(float(top.sum() / bottom.sum()), spread, top.size)


def hierarchical_ci(groups: Sequence[Sequence[float]], *, resamples: int = RESAMPLES,
                    seed: int = DEFAULT_SEED) -> dict:
    """The mean over a method's models of each model's mean over its episodes, with an interval
    from resampling the models and then, within each drawn model, its episodes."""
    kept = [np.asarray([v for v in group if v is not None], dtype=float) for group in groups]
    kept = [group for group in kept if group.size]
    if not kept:
        return {"value": None, "low": None, "high": None, "n": 0}
    rng = np.random.default_rng(seed)
    spread = np.empty(resamples)
    for draw in range(resamples):
        chosen = rng.integers(0, len(kept), size=len(kept))
        spread[draw] = np.mean([kept[i][rng.integers(0, kept[i].size, kept[i].size)].mean()
                                for i in chosen])
    value = float(np.mean([group.mean() for group in kept]))
    return _interval(value, spread, sum(group.size for group in kept))


def _interval(value: float, spread: np.ndarray, n: int) -> dict:
    tail = 100.0 * (1.0 - CONFIDENCE) / 2.0
    low, high = np.percentile(spread, [tail, 100.0 - tail])
    return {"value": round(value, 4), "low": round(float(low), 4),
            "high": round(float(high), 4), "n": int(n)}


def paired_comparison(a: Mapping[str, float], b: Mapping[str, float], *, figure: str,
                      higher_is_better: bool = True, names: tuple[str, str] = ("A", "B"),
                      resamples: int = RESAMPLES, seed: int = DEFAULT_SEED) -> dict:
    """Compare two methods' ``figure`` on the episodes both have (``a``, ``b``: episode key ->
    value). Returns the mean difference A - B, its interval, the permutation p-value, the
    verdict sentence and the episodes needed for a difference of the observed size."""
    keys = sorted(key for key in a.keys() & b.keys()
                  if a[key] is not None and b[key] is not None)
    if len(keys) < 2:
        return {"figure": figure, "episodes": len(keys), "difference": None, "low": None,
                "high": None, "p_value": None, "episodes_needed": None,
                "sentence": f"too few shared episodes ({len(keys)}) to compare {figure}"}
    diffs = np.array([a[key] - b[key] for key in keys], dtype=float)
    interval = bootstrap_ci(diffs, resamples=resamples, seed=seed)
    p_value = sign_flip_p_value(diffs, resamples=resamples, seed=seed)
    needed = episodes_needed(diffs)
    return {"figure": figure, "episodes": len(keys), "difference": interval["value"],
            "low": interval["low"], "high": interval["high"], "p_value": p_value,
            "episodes_needed": needed,
            "sentence": verdict(figure, float(diffs.mean()), p_value, needed, names,
                                higher_is_better)}


def sign_flip_p_value(diffs: np.ndarray, *, resamples: int = RESAMPLES,
                      seed: int = DEFAULT_SEED) -> float:
    """Two-sided p-value of a mean paired difference under "no difference" (each episode's
    difference equally likely either sign), with the observed assignment counted."""
    observed = abs(float(diffs.mean()))
    rng = np.random.default_rng(seed)
    signs = rng.choice((-1.0, 1.0), size=(resamples, diffs.size))
    flipped = np.abs((signs * diffs).mean(axis=1))
    extreme = int(np.count_nonzero(flipped >= observed - 1e-12))
    return round((extreme + 1) / (resamples + 1), 4)


def episodes_needed(diffs: np.ndarray) -> int | None:
    """Episodes a paired comparison needs to detect a mean difference of the observed size at
    :data:`ALPHA` with :data:`POWER` (normal approximation; None when the difference is 0)."""
    from statistics import NormalDist

    mean, spread = float(diffs.mean()), float(diffs.std(ddof=1))
    if mean == 0.0:
        return None
    z = NormalDist().inv_cdf(1.0 - ALPHA / 2.0) + NormalDist().inv_cdf(POWER)
    return max(2, math.ceil((z * spread / abs(mean)) ** 2))


def verdict(figure: str, mean_diff: float, p_value: float, needed: int | None,
            names: tuple[str, str], higher_is_better: bool) -> str:
    """One plain sentence on the comparison."""
    a_name, b_name = names
    if p_value < ALPHA and mean_diff != 0.0:
        better = a_name if (mean_diff > 0) == higher_is_better else b_name
        worse = b_name if better == a_name else a_name
        return f"{better} is better than {worse} in {figure} (p = {p_value:.4f})."
    need = (f"; a difference of this size would need about {needed} paired episodes"
            if needed is not None else "")
    return f"No difference detected in {figure} at this size (p = {p_value:.4f}){need}."
