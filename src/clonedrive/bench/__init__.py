"""Benchmark suites, their episodes run on worker processes, scores and the leaderboard."""

#: The built-in suite that bench and dagger drive unless told otherwise (bench/suites/).
DEFAULT_SUITE = "v4"
#: Episodes one worker drives in lock-step, at most (``BenchConfig.batch``, ``bench --batch``).
MAX_BATCH = 64
