"""The number formats both HTML reports share (report.fmt, pct, iv)."""

from __future__ import annotations

import math

from trustseek.report import fmt, iv, pct


def test_shares_are_percentages_written_as_the_tables_write_numbers():
    assert [pct(x) for x in (0.6, 0.0123, 1.0, 0.0, 1 / 3, 1e-13)] == ["60 %", "1.23 %", "100 %", "0 %", "33.33 %", "0 %"]
    # nothing to show is a dash, never "nan %" or "– %"
    assert [pct(x) for x in (None, math.nan, math.inf)] == ["–", "–", "–"]


def test_intervals_are_the_mean_and_its_ends_in_one_format():
    assert iv({"mean": 0.81712, "lo": 0.44, "hi": 1.19}) == "0.817 [0.440, 1.190]"
    assert iv({"mean": 0.05, "lo": 0.00127, "hi": 0.249}, ".2f") == "0.05 [0.00, 0.25]"
    # the unit once, after the mean
    assert iv({"mean": 0.0074, "lo": 0.004, "hi": 0.0108}, ".3g", 100, " %") == "0.74 % [0.4, 1.08]"
    assert iv({"mean": 2.0, "lo": None, "hi": None}) == "2.000" and iv({"mean": None}) == "–"
    assert fmt(None) == "–" and fmt(3) == "3" and fmt(12345) == "12,345"
