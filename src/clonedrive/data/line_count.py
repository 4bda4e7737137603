"""How many lines a recording's CSV files may have, counted in their raw bytes before any row
is parsed: the driving log (:mod:`clonedrive.data.driving_log`) and its speed labels
(:mod:`clonedrive.data.speed_labels`) share the limit and the count."""

from __future__ import annotations

#: Most lines a driving_log.csv may have (header and blank lines included): 9 hours at 15 Hz,
#: ten times the longest real recording (Udacity logs hold 10,000-50,000 rows). Short rows fit
#: millions into ``driving_log.MAX_LOG_BYTES``, and each row read costs about 1.5 KB there and
#: more in ``train`` (1,000,000 rows: 1.5 GB for ``check``), so they are counted before any is
#: parsed.
MAX_LOG_ROWS = 500_000


def count_lines(raw: bytes) -> int:
    """Lines in ``raw`` as the reader splits them: LF, CRLF or a lone CR each end one, and
    text after the last ending is one more."""
    lines = raw.count(b"\n") + raw.count(b"\r") - raw.count(b"\r\n")
    return lines + 1 if raw and not raw.endswith((b"\n", b"\r")) else lines
