"""Words the report builds from figures."""

from __future__ import annotations

from clonedrive.report import formatting as fmt


def test_listed_joins_with_commas_and_a_final_and() -> None:
    assert fmt.listed([]) == ""
    assert fmt.listed(["15"]) == "15"
    assert fmt.listed(["15", "30"]) == "15 and 30"
    assert fmt.listed(["averaged", "scaled", "held"]) == "averaged, scaled and held"


def test_small_figures_keep_significant_digits() -> None:
    # A gentle track's steering rates: three decimals would print 0.010 and 0.005 for a
    # ratio of 1.98.
    assert (fmt.sig(0.0103984), fmt.sig(0.00525852)) == ("0.0104", "0.00526")
    assert fmt.sig(0.0432775) == "0.0433"
    assert fmt.sig(None) == fmt.sig(float("nan")) == fmt.MISSING
    assert fmt.sig("fast") == fmt.num("fast") == "fast"  # a hand-edited eval.json's text
