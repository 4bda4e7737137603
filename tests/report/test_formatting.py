"""Words the report builds from figures."""

from __future__ import annotations

from clonedrive.report import formatting as fmt


def test_listed_joins_with_commas_and_a_final_and() -> None:
    assert fmt.listed([]) == ""
    assert fmt.listed(["15"]) == "15"
    assert fmt.listed(["15", "30"]) == "15 and 30"
    assert fmt.listed(["averaged", "scaled", "held"]) == "averaged, scaled and held"
