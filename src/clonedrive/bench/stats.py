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
#: Most label assignments a permutation test over models enumerates exactly (beyond: drawn).
EXACT_ASSIGNMENTS = 20000
#: Most resampled values :func:`hierarchical_ci` holds at once (32 MB of indices).
MAX_DRAWN_VALUES = 4_000_000
#: Seed of the generator when the caller gives none.
DEFAULT_SEED = 0


def bootstrap_ci(values: Sequence[float], *, statistic: Callable = np.mean,
                 resamples: int = RESAMPLES, seed: int = DEFAULT_SEED) -> dict:
    """``{"value", "low", "high", "n"}``: the statistic of ``values`` and its percentile
    interval over resampled episodes (None for no values; one value has no spread)."""
    data = np.asarray([v for v in values if v is not None], dtype=float)
    if data.size == 0:
        return {"value": None, "low": None, "high": None, "n": 0}
    spread = np.concatenate([statistic(data[draws], axis=1)
                             for draws in _draws(seed, resamples, data.size)])
    return _interval(float(statistic(data)), spread, data.size)


def _draws(seed: int, resamples: int, size: int):
    """``resamples`` rows of ``size`` episode indices drawn with replacement, in blocks of at
    most :data:`MAX_DRAWN_VALUES` values: the same rows, in the same order, as one draw of
    ``(resamples, size)`` (the generator is consumed value by value), in bounded memory."""
    rng = np.random.default_rng(seed)
    rows = max(1, MAX_DRAWN_VALUES // max(size, 1))
    for start in range(0, resamples, rows):
        yield rng.integers(0, size, size=(min(rows, resamples - start), size))


def ratio_ci(numerators: Sequence[float], denominators: Sequence[float], *,
             resamples: int = RESAMPLES, seed: int = DEFAULT_SEED) -> dict:
    """A pooled ratio (sum of numerators / sum of denominators, e.g. interventions per km) and
    its interval over resampled episodes (None where the denominators sum to 0)."""
    top = np.asarray(numerators, dtype=float)
    bottom = np.asarray(denominators, dtype=float)
    if top.size == 0 or bottom.sum() <= 0:
        return {"value": None, "low": None, "high": None, "n": int(top.size)}
    tops, sums = [], []
    for draws in _draws(seed, resamples, top.size):
        tops.append(top[draws].sum(axis=1))
        sums.append(bottom[draws].sum(axis=1))
    drawn_top, drawn_sum = np.concatenate(tops), np.concatenate(sums)
    spread = np.where(drawn_sum > 0, drawn_top / np.where(drawn_sum > 0, drawn_sum, 1.0),
                      np.nan)
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
    chosen = rng.integers(0, len(kept), size=(resamples, len(kept)))
    # Each time model i is drawn it gets its own resample of its episodes; all of model i's
    # resamples are drawn at once, as one array (the loop is over models, not resamples).
    means = np.empty(chosen.shape)
    for index, group in enumerate(kept):
        drawn = chosen == index
        means[drawn] = _resampled_means(group, int(drawn.sum()), rng)
    value = float(np.mean([group.mean() for group in kept]))
    return _interval(value, means.mean(axis=1), sum(group.size for group in kept))


def _resampled_means(group: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` means of ``group`` resampled with replacement, drawn at most
    :data:`MAX_DRAWN_VALUES` values at a time (bounded memory for any number of episodes)."""
    rows = max(1, MAX_DRAWN_VALUES // group.size)
    parts = [group[rng.integers(0, group.size, size=(min(rows, count - start), group.size))]
             .mean(axis=1) for start in range(0, count, rows)]
    return np.concatenate(parts) if parts else np.empty(0)


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


def seed_comparison(a_models: Sequence[Mapping[str, float]],
                    b_models: Sequence[Mapping[str, float]], *, figure: str,
                    higher_is_better: bool = True, names: tuple[str, str] = ("A", "B"),
                    resamples: int = RESAMPLES, seed: int = DEFAULT_SEED) -> dict:
    """Two methods compared over their training seeds as well as their episodes (each of
    ``a_models``, ``b_models``: one model's episode key -> value), on the episodes every model
    drove. The difference of the methods' means has an interval from resampling each method's
    models and the shared episodes (paired); the p-value is an exact permutation test of the
    models' labels on their means, which is what generalises to another training seed; and
    ``seeds_needed`` is how many seeds per method a difference of the observed size would
    need (two-sample normal approximation on the models' means)."""
    keys = sorted(set.intersection(*[{k for k, v in model.items() if v is not None}
                                     for model in [*a_models, *b_models]]))
    base = {"figure": figure, "models": [len(a_models), len(b_models)], "episodes": len(keys)}
    if len(keys) < 2 or min(len(a_models), len(b_models)) < 1:
        return {**base, "difference": None, "sentence": f"too few shared episodes "
                                                        f"({len(keys)}) to compare {figure}"}
    a = np.array([[model[key] for key in keys] for model in a_models], dtype=float)
    b = np.array([[model[key] for key in keys] for model in b_models], dtype=float)
    rng = np.random.default_rng(seed)
    spread = np.empty(resamples)
    for draw in range(resamples):
        episodes = rng.integers(0, len(keys), len(keys))
        spread[draw] = (a[rng.integers(0, len(a), len(a))][:, episodes].mean()
                        - b[rng.integers(0, len(b), len(b))][:, episodes].mean())
    interval = _interval(float(a.mean() - b.mean()), spread, len(keys))
    means_a, means_b = a.mean(axis=1), b.mean(axis=1)
    p_value, smallest = label_permutation_p(means_a, means_b, seed=seed)
    sign = 1.0 if higher_is_better else -1.0
    wins = float(np.mean([sign * (x - y) > 0 for x in means_a for y in means_b]))
    needed = seeds_needed(means_a, means_b)
    return {**base, "difference": interval["value"], "low": interval["low"],
            "high": interval["high"], "p_value": p_value, "smallest_p": smallest,
            "a_model_means": [round(float(x), 4) for x in means_a],
            "b_model_means": [round(float(y), 4) for y in means_b],
            "a_beats_b_share": round(wins, 4), "seeds_needed": needed,
            "sentence": seed_verdict(figure, interval, p_value, smallest, needed, names,
                                     higher_is_better, (len(a), len(b)))}


def label_permutation_p(a: np.ndarray, b: np.ndarray, *, exact_limit: int = EXACT_ASSIGNMENTS,
                        draws: int = RESAMPLES, seed: int = DEFAULT_SEED) -> tuple[float, float]:
    """(two-sided p-value, the smallest p-value these group sizes can give) of the difference
    of means between groups ``a`` and ``b`` under exchangeable labels: exact over every
    assignment when there are at most ``exact_limit`` of them, else from ``draws`` random
    ones with the observed assignment counted (so never 0)."""
    pooled = np.concatenate([a, b])
    observed = abs(float(a.mean() - b.mean()))
    exact = math.comb(pooled.size, a.size) <= exact_limit
    diffs = _assignment_differences(pooled, a.size, None if exact else draws, seed)
    extreme = int(np.count_nonzero(diffs >= observed - 1e-12))
    if exact:
        p_value = extreme / diffs.size
        smallest = float(np.mean(diffs >= diffs.max() - 1e-12))
    else:
        p_value, smallest = (extreme + 1) / (draws + 1), 1.0 / (draws + 1)
    return round(p_value, 4), round(smallest, 4)


def _assignment_differences(pooled: np.ndarray, size_a: int, draws: int | None,
                            seed: int) -> np.ndarray:
    """|mean of group A - mean of the rest| for every way to pick ``size_a`` of ``pooled`` as
    group A (``draws`` None), or for ``draws`` random picks."""
    from itertools import combinations

    if draws is None:
        groups = np.array(list(combinations(range(pooled.size), size_a)))
    else:
        rng = np.random.default_rng(seed)
        groups = np.array([rng.permutation(pooled.size)[:size_a] for _ in range(draws)])
    inside = np.zeros((len(groups), pooled.size), dtype=bool)
    np.put_along_axis(inside, groups, True, axis=1)
    in_a = (inside * pooled).sum(axis=1)
    return np.abs(in_a / size_a - (pooled.sum() - in_a) / (pooled.size - size_a))


def seeds_needed(a: np.ndarray, b: np.ndarray) -> int | None:
    """Seeds per method that detect a difference of means of the observed size at
    :data:`ALPHA` with :data:`POWER`, from the models' means (None when either method has one
    model, or the difference is 0)."""
    if a.size < 2 or b.size < 2 or a.mean() == b.mean():
        return None
    spread = math.sqrt((a.var(ddof=1) + b.var(ddof=1)) / 2.0)
    z = _detection_z()
    return max(2, math.ceil(2.0 * (z * spread / abs(float(a.mean() - b.mean()))) ** 2))


def seed_verdict(figure: str, interval: dict, p_value: float, smallest: float,
                 needed: int | None, names: tuple[str, str], higher_is_better: bool,
                 counts: tuple[int, int]) -> str:
    """One plain sentence on a comparison over seeds."""
    sizes = f"{counts[0]} against {counts[1]} models"
    if p_value < ALPHA:
        better = names[0] if (interval["value"] > 0) == higher_is_better else names[1]
        return (f"Over training seeds too, {better} is better in {figure} "
                f"(p = {p_value:.4f}, {sizes}).")
    floor = (f"; {sizes} cannot give a p-value below {smallest:.4f}" if smallest >= ALPHA
             else "")
    need = f"; about {needed} seeds per method would be needed" if needed else ""
    return (f"Over training seeds, no difference detected in {figure} "
            f"(p = {p_value:.4f}{floor}{need}).")


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
    mean, spread = float(diffs.mean()), float(diffs.std(ddof=1))
    if mean == 0.0:
        return None
    z = _detection_z()
    return max(2, math.ceil((z * spread / abs(mean)) ** 2))


def _detection_z() -> float:
    """The normal quantiles a two-sided test at :data:`ALPHA` with :data:`POWER` needs between
    the observed difference and its standard error."""
    from statistics import NormalDist

    return NormalDist().inv_cdf(1.0 - ALPHA / 2.0) + NormalDist().inv_cdf(POWER)


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
