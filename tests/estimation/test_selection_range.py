"""A choice at the largest number compared: the warning names the wider range to compare, or,
at the most a command compares, says the choice is a lower bound (no option it would refuse)."""

from __future__ import annotations

from trustseek.estimation.selection import MAX_LEVELS, MAX_TYPES, selection_warnings, type_selection_warnings


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


def test_the_range_widens_while_the_best_is_the_largest_compared():
    """select and select-types compare one more while a criterion's best is the largest compared,
    up to their cap; without a cap (--no-widen) only the numbers asked."""
    from trustseek.estimation.selection import widening

    def run(asked, scores, cap):  # scores[k]: (bic, held-out) of k, lower BIC and higher held-out better
        rows, seen = [], []
        for k in widening(asked, rows, "levels", cap):
            seen.append(k)
            rows.append({"levels": k, "bic": scores[k][0], "heldout_loglik": scores[k][1]})
        return seen

    rising = {k: (-k, k) for k in range(1, 20)}  # every criterion prefers more
    assert run([1, 2], rising, 0) == [1, 2]
    assert run([1, 2], rising, MAX_LEVELS) == list(range(1, MAX_LEVELS + 1))
    peaked = {k: (abs(k - 3), -abs(k - 3)) for k in range(1, 20)}  # both best at 3
    assert run([1, 2], peaked, MAX_LEVELS) == [1, 2, 3, 4]
    assert run([1, 2, 3, 4, 5], peaked, MAX_LEVELS) == [1, 2, 3, 4, 5]
    split = {k: (-k if k < 4 else 0, -abs(k - 2)) for k in range(1, 20)}  # BIC best at 3, held-out at 2
    assert run([1, 2], split, MAX_TYPES) == [1, 2, 3, 4]
