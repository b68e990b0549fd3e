"""A choice at the largest number compared: the warning names the wider range to compare, or,
at the most a command compares, says the choice is a lower bound (no option it would refuse)."""

from __future__ import annotations

from trustseek.estimation.selection import MAX_LEVELS, selection_warnings
from trustseek.estimation.type_selection import MAX_TYPES, type_selection_warnings


def _rows(key: str, top: int) -> list[dict]:
    return [
        {key: top - 1, "best_heldout": False, "best_bic": True, "starts": 3, "reached_best": 3},
        {key: top, "best_heldout": True, "best_bic": False, "starts": 3, "reached_best": 3},
    ]


def test_a_best_at_the_top_asks_for_a_wider_range_or_says_it_is_a_lower_bound():
    assert "compare more with --max-levels 5" in selection_warnings(_rows("levels", 4))[0]
    at_cap = selection_warnings(_rows("levels", MAX_LEVELS))[0]
    assert f"--max-levels {MAX_LEVELS + 1}" not in at_cap and f"at least {MAX_LEVELS}" in at_cap
    assert "compare more with --types 2..4" in type_selection_warnings(_rows("types", 3))[0]
    at_cap = type_selection_warnings(_rows("types", MAX_TYPES))[0]
    assert f"..{MAX_TYPES + 1}" not in at_cap and f"at least {MAX_TYPES}" in at_cap
