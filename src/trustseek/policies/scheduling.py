"""The scheduling policy (kind ``schedule``): which kind of item to collect next, and whether to ask.

A :class:`SchedulePolicy` answers a bigger question than a :class:`~.base.Policy`: given the
belief over trust, the remaining items per complexity and the visible ones, it picks a
complexity among the visible items *and* the robot action (``choose`` / ``choices``).  It
stores, for every state (remaining, visible) and every visible complexity k, the functions
Q(x, k, autonomous) and Q(x, k, ask) of x = P(trust = high) as piecewise-linear functions
(breakpoints and values: exact for the alpha-vector method, a uniform grid otherwise).

It is still a ``Policy``: bound to one state with :meth:`SchedulePolicy.at`, ``actions(beliefs,
complexities)`` is the ask decision for an item of a given complexity in that state (what a
robot needs when the item is imposed).  :class:`ScheduleRunner` extends ``PolicyRunner``: it
keeps the belief *and* the remaining items, ``choose()`` before a trial, ``observe`` after it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..model.core import TrustModel
from ..model.jsonfile import ModelError
from ..pomdp.belief import to_vector
from ..pomdp.scheduling import Counts, State, parse_state_key, state_key
from ..vocab import ACTIONS, ASK, AUTONOMOUS
from .base import Policy, PolicyError, planned_for
from .regions import Interval, ask_intervals
from .runner import PolicyRunner

SCHEDULE = "schedule"
TIE = 1e-12  # a later (complexity, action) must beat an earlier one by more than this


@dataclass(frozen=True)
class PieceQ:
    """Q(x, k, a) of one state and complexity: values[:, a] at breakpoints xs (linear in between)."""

    xs: np.ndarray
    values: np.ndarray  # (len(xs), 2)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """(len(x), 2)."""
        return np.stack([np.interp(x, self.xs, self.values[:, a]) for a in range(2)], axis=-1)

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        """The breakpoints and the values side by side, (len(xs), 3): what a check of the numbers reads."""
        out = np.column_stack([self.xs, self.values])
        return out if dtype is None else out.astype(dtype)


@dataclass(eq=False, repr=False)
class SchedulePolicy(Policy):
    """Greedy in Q(x, state, k, a) over the visible complexities k and the actions a (ties go to
    the lower complexity index, then to ``autonomous``)."""

    kind = SCHEDULE
    q: Mapping[State, Mapping[int, PieceQ]]
    model: TrustModel = field()  # field(): required, not the base class default
    complexities: tuple[str, ...] = field()
    belief_update: str = field()
    counts: Sequence[int]
    window: int | None
    info: dict[str, Any] = field(default_factory=dict)
    state: State | None = None

    def __post_init__(self) -> None:
        self.q = dict(self.q)
        self.complexities = tuple(self.complexities)
        self.counts = tuple(int(k) for k in self.counts)
        self.info = dict(self.info or {})
        starts = [s for s in self.q if s[0] == self.counts]
        self.state = self.state if self.state is not None else (starts[0] if len(starts) == 1 else None)

    # -- the scheduling interface --------------------------------------------------------
    def _state(self, remaining: Sequence[int], visible: Sequence[int] | None) -> State:
        rem = tuple(int(k) for k in remaining)
        if visible is None:
            if self.window is not None and sum(rem) > self.window:
                raise PolicyError([f"this policy sees a window of {self.window} items: give the visible items"])
            vis = rem
        else:
            vis = tuple(int(k) for k in visible)
        s = (rem, vis)
        if s not in self.q:
            raise PolicyError([f"state remaining={list(rem)}, visible={list(vis)} is not one this policy was solved for"])
        return s

    def q_table(self, x: Any, state: State) -> np.ndarray:
        """Q(x, state, k, a), shape (len(x), N, 2); NaN for complexities not visible."""
        x = np.atleast_1d(np.asarray(x, dtype=float))
        out = np.full((len(x), len(self.complexities), 2), np.nan)
        for k, fn in self.q[state].items():
            out[:, k] = fn(x)
        return out

    def _best(self, x: np.ndarray, state: State) -> tuple[np.ndarray, np.ndarray]:
        best = np.full(len(x), -np.inf)
        item = np.zeros(len(x), dtype=np.int64)
        act = np.zeros(len(x), dtype=np.int64)
        for k in sorted(self.q[state]):
            qk = self.q[state][k](x)
            for a in (AUTONOMOUS, ASK):
                better = qk[:, a] > best + TIE
                best = np.where(better, qk[:, a], best)
                item = np.where(better, k, item)
                act = np.where(better, a, act)
        return item, act

    def choose(self, belief: Any, remaining: Sequence[int], visible: Sequence[int] | None = None) -> tuple[int, int]:
        s = self._state(remaining, visible)
        x = np.array([_high(belief, self.model)])
        item, act = self._best(x, s)
        return int(item[0]), int(act[0])

    def choices(
        self, beliefs: np.ndarray, remaining: np.ndarray, visible: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        b = np.asarray(beliefs, dtype=float)
        x = b[:, -1] if b.ndim == 2 else b
        rem = np.asarray(remaining, dtype=np.int64)
        vis = rem if visible is None else np.asarray(visible, dtype=np.int64)
        keys = np.concatenate([rem, vis], axis=1)
        items = np.zeros(len(x), dtype=np.int64)
        acts = np.zeros(len(x), dtype=np.int64)
        uniq, inv = np.unique(keys, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        N = rem.shape[1]
        for j, key in enumerate(uniq):
            sel = inv == j
            s = self._state(key[:N], None if visible is None else key[N:])
            items[sel], acts[sel] = self._best(x[sel], s)
        return items, acts

    def start_value(self) -> float:
        """The expected value of the session from the model's initial trust, over the start
        states (``info['start']``)."""
        assert self.model is not None
        x = np.array([_high(self.model.initial, self.model)])
        starts = self.info.get("start", {})
        return sum((p * float(np.nanmax(self.q_table(x, parse_state_key(k)))) for k, p in starts.items()), 0.0)

    # -- bound to one state: a plain Policy -------------------------------------------------
    def at(self, remaining: Sequence[int], visible: Sequence[int] | None = None) -> SchedulePolicy:
        """This policy bound to a state: ``actions`` then decides for an item of a given complexity."""
        return replace(self, state=self._state(remaining, visible))

    def _bound(self) -> State:
        if self.state is None:
            raise PolicyError(["this scheduling policy is not bound to a state: use at(remaining, visible)"])
        return self.state

    def actions(self, beliefs: np.ndarray | None, complexities: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        s = self._bound()
        b = np.asarray(beliefs, dtype=float)
        x = b[..., -1]
        c = np.asarray(complexities, dtype=np.int64)
        out = np.zeros(len(c), dtype=np.int64)
        for k in np.unique(c):
            if int(k) not in self.q[s]:
                raise PolicyError([f"no {self.complexities[int(k)]} item is visible in state {state_key(s)}"])
            sel = c == k
            qk = self.q[s][int(k)](x[sel])
            out[sel] = np.where(qk[:, ASK] > qk[:, AUTONOMOUS] + TIE, ASK, AUTONOMOUS)
        return out

    def q_values(self, b_high: Any) -> np.ndarray:
        x = np.asarray(b_high, dtype=float)
        return self.q_table(x.reshape(-1), self._bound()).reshape(*x.shape, len(self.complexities), 2)

    def ask_intervals(self) -> dict[str, list[Interval]]:
        s = self._bound()
        out: dict[str, list[Interval]] = {}
        for k, fn in sorted(self.q[s].items()):
            out[self.complexities[k]] = ask_intervals(fn.xs, fn.values[:, ASK] - fn.values[:, AUTONOMOUS])
        return out

    # -- description and JSON ---------------------------------------------------------------
    def describe(self) -> str:
        items = " + ".join(f"{k} {c}" for k, c in zip(self.counts, self.complexities, strict=True))
        view = "full control" if self.window is None else f"window {self.window}"
        return f"{self.kind} ({items}, {view}, {self.belief_update} belief, {len(self.q)} states)"

    def overview(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "counts": dict(zip(self.complexities, self.counts, strict=True)),
            "window": self.window,
            "belief_update": self.belief_update,
            "states": len(self.q),
            "value": self.info.get("value"),
        }

    def _uniform_grid(self) -> int | None:
        """The number of points when every Q is tabulated on the same uniform grid, else None."""
        sizes = {len(fn.xs) for per_k in self.q.values() for fn in per_k.values()}
        if len(sizes) != 1:
            return None
        g = np.linspace(0.0, 1.0, sizes.pop())
        same = all(np.array_equal(fn.xs, g) for per_k in self.q.values() for fn in per_k.values())
        return len(g) if same else None

    def to_dict(self) -> dict[str, Any]:
        """The policy JSON; a Q tabulated on a uniform grid is written without its breakpoints
        (``grid`` holds their number) and with values to 10 decimals."""
        assert self.model is not None
        grid = self._uniform_grid()
        states = {}
        for s, per_k in self.q.items():
            entry = {}
            for k, fn in sorted(per_k.items()):
                t: dict[str, list[float]] = {} if grid is not None else {"x": fn.xs.tolist()}
                for a, an in enumerate(ACTIONS):
                    v = fn.values[:, a]
                    t[an] = np.round(v, 10).tolist() if grid is not None else v.tolist()
                entry[self.complexities[k]] = t
            states[state_key(s)] = entry
        return self._file(
            belief_update=self.belief_update,
            counts=list(self.counts),
            window=self.window,
            grid=grid,
            info=self.info,
            model=self.model.to_dict(),
            states=states,
        )

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], source: str | None = None) -> SchedulePolicy:
        cx, model, bu = planned_for(d, source)
        counts, window = d.get("counts"), d.get("window")
        if not isinstance(counts, list) or len(counts) != len(cx) or not all(isinstance(k, int) and k >= 0 for k in counts):
            raise ModelError([f"counts must be one non-negative integer per complexity, got {counts!r}"], source)
        if window is not None and (not isinstance(window, int) or window < 1):
            raise ModelError([f"window must be a positive integer or null, got {window!r}"], source)
        q: dict[State, dict[int, PieceQ]] = {}
        grid = d.get("grid")
        if grid is not None and (not isinstance(grid, int) or grid < 2):
            raise ModelError([f"grid must be a number of points (at least 2) or null, got {grid!r}"], source)
        uniform = None if grid is None else np.linspace(0.0, 1.0, grid)
        try:
            for key, per_k in dict(d["states"]).items():
                s = parse_state_key(key)
                q[s] = {}
                for cn, t in per_k.items():
                    xs = uniform if uniform is not None else np.asarray(t["x"], dtype=float)
                    vals = np.stack([np.asarray(t[an], dtype=float) for an in ACTIONS], axis=1)
                    if vals.shape != (len(xs), 2) or len(xs) < 2:
                        raise ValueError
                    q[s][cx.index(cn)] = PieceQ(xs, vals)
        except (KeyError, TypeError, ValueError):
            raise ModelError(
                ["states must map 'remaining/visible' to, per visible complexity, breakpoints x and Q per action"], source
            ) from None
        return cls(q, model, tuple(cx), bu, counts, window, d.get("info") or {})


def _high(belief: Any, model: TrustModel | None) -> float:
    n_trust = model.n_trust if model is not None else 2
    if n_trust != 2:
        raise PolicyError([f"a scheduling policy needs two trust levels; this model has {n_trust}"])
    return float(to_vector(belief, 2)[-1])


@dataclass
class ScheduleRunner(PolicyRunner):
    """A scheduling policy with its live belief and the remaining items.

    ``choose(visible)`` before a trial gives (complexity, action); ``observe`` after it updates
    the belief and takes the item off the remaining ones.  ``decide(complexity)`` (inherited)
    gives the action for an imposed item in the current state."""

    remaining: Counts | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        pol = self.policy
        if not isinstance(pol, SchedulePolicy):
            raise PolicyError([f"a schedule runner needs a {SCHEDULE} policy, got a {pol.kind} policy"])
        self.remaining = tuple(pol.counts) if self.remaining is None else tuple(int(k) for k in self.remaining)
        self.visible: Counts | None = None

    @property
    def schedule_policy(self) -> SchedulePolicy:
        assert isinstance(self.policy, SchedulePolicy)
        return self.policy

    def choose(self, visible: Sequence[int] | Mapping[str, int] | None = None) -> tuple[str, str]:
        """(complexity, robot action) of the next trial; ``visible``: the items the robot sees
        (per complexity, as a sequence or by name; None: every remaining item)."""
        pol = self.schedule_policy
        assert self.remaining is not None
        if sum(self.remaining) == 0:
            raise PolicyError(["no items remain"])
        if isinstance(visible, Mapping):
            visible = [int(visible.get(c, 0)) for c in pol.complexities]
        self.visible = None if visible is None else tuple(int(k) for k in visible)
        k, a = pol.choose(self.belief, self.remaining, self.visible)
        return pol.complexities[k], ACTIONS[a]

    def decide(self, complexity: int | str) -> str:
        assert self.remaining is not None
        return ACTIONS[self.schedule_policy.at(self.remaining, self.visible).action(self.belief, complexity, self.rng)]

    def observe(self, complexity: int | str, action: str, human_action: str | None, experience: str) -> np.ndarray | None:
        c = self.policy.complexity_index(complexity)
        assert self.remaining is not None
        if self.remaining[c] < 1:
            raise PolicyError([f"no {self.policy.complexities[c]} item remains"])
        out = super().observe(complexity, action, human_action, experience)
        self.remaining = tuple(r - (i == c) for i, r in enumerate(self.remaining))
        self.visible = None
        return out
