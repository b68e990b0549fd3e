"""Trial scheduling: the robot chooses which kind of item to collect next, and whether to ask.

A session holds a known number of items of each complexity (``counts``; experiment 2 of
the paper has 17 low and 17 high).  Before each trial the robot sees the next ``window``
items of a queue in random order (``window=None``: every remaining item, full control;
``window=1``: the next item only, the paper's setting of a random order with known counts),
picks one of the visible items and decides whether to ask.  The trust model, the reward of
eq. (1) and the belief update are those of the :class:`AssistancePOMDP`; the horizon is the
number of items.

A *state* is (remaining, visible): the remaining items per complexity and the visible ones
per complexity (``visible <= remaining``, ``sum(visible) = min(window, sum(remaining))``);
both are observed, trust stays hidden.  Picking complexity k leads to the *afterstate*
(remaining - e_k, visible - e_k); then the next item of the queue (complexity j with
probability hidden_j / sum(hidden), hidden = remaining - visible) enters the window.
With full control visible = remaining throughout.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from math import comb, prod

from ..errors import TrustseekError
from .problem import AssistancePOMDP

Counts = tuple[int, ...]
State = tuple[Counts, Counts]  # (remaining, visible)


class SchedulingError(TrustseekError, ValueError):
    """A scheduling problem that cannot be built as asked (bad counts or window)."""


@dataclass(frozen=True, eq=False)
class SchedulingProblem:
    """An assistance POMDP over a session of ``counts`` items, ``window`` of them visible."""

    pomdp: AssistancePOMDP
    counts: Counts
    window: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "counts", tuple(int(k) for k in self.counts))
        problems = []
        N = self.pomdp.n_complexity
        if len(self.counts) != N or any(k < 0 for k in self.counts) or sum(self.counts) < 1:
            problems.append(
                f"counts must give a non-negative number of items for each of {list(self.pomdp.complexities)} "
                f"with at least one item, got {list(self.counts)}"
            )
        if self.window is not None and (int(self.window) != self.window or self.window < 1):
            problems.append(f"the window must be a positive number of items or None (every item), got {self.window!r}")
        if problems:
            raise SchedulingError(problems)
        if self.window is not None and self.window >= sum(self.counts):
            object.__setattr__(self, "window", None)  # seeing every item is full control

    @classmethod
    def build(
        cls, pomdp: AssistancePOMDP, counts: Sequence[int] | dict[str, int], window: int | None = None
    ) -> SchedulingProblem:
        """``counts`` as a sequence or by complexity name."""
        if isinstance(counts, dict):
            unknown = [k for k in counts if k not in pomdp.complexities]
            if unknown:
                raise SchedulingError(
                    [f"unknown complexity {unknown[0]!r} in counts; expected one of {list(pomdp.complexities)}"]
                )
            counts = [int(counts.get(c, 0)) for c in pomdp.complexities]
        return cls(pomdp, tuple(counts), window)

    # -- sizes ---------------------------------------------------------------
    @property
    def complexities(self) -> tuple[str, ...]:
        return self.pomdp.complexities

    @property
    def horizon(self) -> int:
        return sum(self.counts)

    @property
    def full_control(self) -> bool:
        return self.window is None

    def shown(self, remaining: Counts) -> int:
        """How many items are visible when ``remaining`` are left."""
        n = sum(remaining)
        return n if self.window is None else min(self.window, n)

    def trial(self, state: State) -> int:
        """The index (from 0) of the trial about to be run in ``state``."""
        return self.horizon - sum(state[0])

    def describe(self) -> str:
        items = " + ".join(f"{k} {c}" for k, c in zip(self.counts, self.complexities, strict=True))
        view = "full control" if self.full_control else f"window {self.window}"
        return f"{items} items, {view}"

    # -- dynamics ------------------------------------------------------------
    def draws(self, hidden: Counts, m: int, visible: Counts | None = None) -> list[tuple[Counts, float]]:
        """The compositions of ``m`` items drawn without replacement from ``hidden``, each added
        to ``visible``, with their (multivariate hypergeometric) probabilities."""
        base = visible or (0,) * len(hidden)
        total = comb(sum(hidden), m)
        out = []
        for comp in _compositions(m, hidden):
            p = prod(comb(h, k) for h, k in zip(hidden, comp, strict=True)) / total
            out.append((tuple(b + k for b, k in zip(base, comp, strict=True)), p))
        return out

    def start(self) -> list[tuple[State, float]]:
        """The states the session can start in, with their probabilities."""
        return [((self.counts, v), p) for v, p in self.draws(self.counts, self.shown(self.counts))]

    def picks(self, state: State) -> list[int]:
        """The complexities the robot can pick in ``state`` (those visible)."""
        return [k for k, v in enumerate(state[1]) if v > 0]

    def after(self, state: State, k: int) -> State:
        """The afterstate of picking complexity ``k``."""
        rem, vis = state
        if vis[k] < 1:
            raise SchedulingError([f"no {self.complexities[k]} item is visible in state {state}"])
        return _minus(rem, k), _minus(vis, k)

    def arrivals(self, afterstate: State) -> list[tuple[State, float]]:
        """The next states of an afterstate (the next queued item enters the window)."""
        rem, vis = afterstate
        if sum(rem) == 0:
            return []
        hidden = tuple(r - v for r, v in zip(rem, vis, strict=True))
        if self.window is None or sum(hidden) == 0:
            return [((rem, vis), 1.0)]
        return [((rem, v), p) for v, p in self.draws(hidden, self.shown(rem) - sum(vis), vis)]

    def states(self) -> list[State]:
        """Every reachable state, in order of decreasing remaining items (backward induction
        runs through them reversed)."""
        frontier = [s for s, _ in self.start()]
        seen: dict[State, None] = dict.fromkeys(frontier)
        while frontier:
            nxt = []
            for s in frontier:
                for k in self.picks(s):
                    for s2, _ in self.arrivals(self.after(s, k)):
                        if s2 not in seen:
                            seen[s2] = None
                            nxt.append(s2)
            frontier = nxt
        return sorted(seen, key=lambda s: (-sum(s[0]), s))


def schedule_size(counts: tuple[int, ...], window: int | None, grid: int) -> int:
    """An upper bound on the number of Q values of a schedule policy (without enumerating its
    states): prod(counts + 1) remaining states, times the visible compositions of a window,
    times complexities, actions and grid points."""
    states = prod(k + 1 for k in counts)
    if window is not None and window < sum(counts):
        states *= (window + 1) ** (len(counts) - 1)
    return states * len(counts) * 2 * grid


def _minus(c: Counts, k: int) -> Counts:
    return tuple(x - (i == k) for i, x in enumerate(c))


def _compositions(m: int, caps: Counts) -> Iterator[Counts]:
    """Every (k_1, ..., k_N) with sum m and 0 <= k_i <= caps_i."""
    if len(caps) == 1:
        if m <= caps[0]:
            yield (m,)
        return
    for k in range(min(m, caps[0]) + 1):
        for rest in _compositions(m - k, caps[1:]):
            yield (k, *rest)


def state_key(state: State) -> str:
    """The state as text, ``"remaining/visible"`` (e.g. ``"3,2/1,2"``), as policy files hold it."""
    return ",".join(map(str, state[0])) + "/" + ",".join(map(str, state[1]))


def parse_state_key(key: str) -> State:
    rem, vis = key.split("/")
    return tuple(int(x) for x in rem.split(",")), tuple(int(x) for x in vis.split(","))
