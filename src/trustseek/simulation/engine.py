"""Simulated supervisors: a vectorized Monte-Carlo model of the object-collection task.

Each simulated *participant* is a supervisor drawn from a :class:`~trustseek.model.TrustModel`
who works through one or more *blocks* of trials, each block under one robot policy.
Trial ``t`` of a participant runs in the order of Sections III-IV:

1. the trial's complexity ``C_t`` comes from the participant's schedule;
2. the robot picks ``a_t`` from its current belief ``b_t`` (``policy.actions``);
3. the human action follows the emission table, ``o_t ~ P(o | T_t, C_t, a_t)``;
4. the experience follows the task, ``E_{t+1} ~ P(E | o_t, C_t, a_t)`` (autonomous success
   with probability ``Task.success[C]``, ``Task.ask_experience[C]`` when the robot asks);
5. the reward is eq. (1), ``Task.reward_table()[a, o, E]``;
6. the hidden trust moves, ``T_{t+1} ~ P(T' | T_t, E_{t+1}, C_t, a_t)``, and the robot
   updates its belief with the policy's updater (``paper`` or ``bayes``).

All participants advance together, one trial at a time, as numpy arrays of shape
``(n_participants,)`` (processed in chunks of :data:`CHUNK` participants).  Every trial
draws the same three uniforms per participant whatever the robot does, from a
generator separate from the policy's, so two runs with the same seed and different
policies face the *same* supervisors, schedules and luck (common random numbers):
differences between policies are paired.

The hidden trust ``T_t`` recorded with a trial is the trust at the start of that trial
(the one that drives ``o_t``); ``belief`` is the robot's P(trust = highest level) when it
chose ``a_t``.

Populations (:class:`Supervisors`): everyone shares one model (``pooled``), each
participant draws their own rows around a pooled model (``dirichlet``; the paper's
Remark 1 on conservative individuals), or participants take models from a list
(``from_models``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import pandas as pd

from ..policies.regions import ask_bounds
from ..pomdp.belief import ScalarBelief, make_updater
from ..vocab import PAPER_BLOCK_COUNTS, TRIAL_COLUMNS, check_belief_update
from ..errors import TrustseekError
from ..model.core import ACTIONS, ASK, AUTONOMOUS, EXPERIENCES, HUMAN_ACTIONS, INTERVENE, RELIABLE, RELY, Task, TrustModel

CHUNK = 1 << 14  # participants simulated together (fits the working set in cache)

# outcome code of a trial: (a * 2 + o) * 2 + e
CODE_INTERVENE = (AUTONOMOUS * 2 + INTERVENE) * 2 + 0
CODE_FAILURE = (AUTONOMOUS * 2 + RELY) * 2 + 0
CODE_SUCCESS = (AUTONOMOUS * 2 + RELY) * 2 + RELIABLE

EXTRA_COLUMNS = ("block", "policy", "true_trust", "belief", "reward")
SUMMARY_COLUMNS = (
    "participant",
    "block",
    "policy",
    "trials",
    "cumulative_reward",
    "discounted_reward",
    "autonomous_collections",
    "failures",
    "interventions",
    "asks",
)


class SimulationError(TrustseekError, ValueError):
    """Inconsistent simulation inputs (shapes, names, counts)."""


# --------------------------------------------------------------------------- populations


@dataclass(frozen=True, eq=False)
class Supervisors:
    """Per-participant supervisor parameters.

    ``initial[p]``, ``emission[p]`` and ``transition[p]`` hold the arrays of a
    :class:`TrustModel` for parameter row ``p``; participant ``i`` uses row ``index[i]``.
    """

    trust_levels: tuple[str, ...]
    complexities: tuple[str, ...]
    initial: np.ndarray  # (P, K)
    emission: np.ndarray  # (P, N, 2, K, 2)
    transition: np.ndarray  # (P, N, 2, 2, K, K)
    index: np.ndarray  # (n,)

    @property
    def n(self) -> int:
        return len(self.index)

    @property
    def n_rows(self) -> int:
        return self.initial.shape[0]

    @property
    def n_trust(self) -> int:
        return len(self.trust_levels)

    @classmethod
    def pooled(cls, model: TrustModel, n: int) -> "Supervisors":
        """``n`` participants who all behave like ``model``."""
        _check_n(n)
        return cls(
            model.trust_levels,
            model.complexities,
            model.initial[None],
            model.emission[None],
            model.transition[None],
            np.zeros(n, dtype=np.int64),
        )

    @classmethod
    def from_models(cls, models: Sequence[TrustModel], n: int | None = None) -> "Supervisors":
        """Participant ``i`` behaves like ``models[i % len(models)]`` (``n`` defaults to ``len(models)``)."""
        if not models:
            raise SimulationError(["from_models needs at least one model"])
        first = models[0]
        for j, m in enumerate(models):
            if m.trust_levels != first.trust_levels or m.complexities != first.complexities:
                raise SimulationError(
                    [f"model {j} has trust levels {list(m.trust_levels)} and complexities {list(m.complexities)}; "
                     f"expected {list(first.trust_levels)} and {list(first.complexities)} like model 0"]
                )
        n = len(models) if n is None else n
        _check_n(n)
        return cls(
            first.trust_levels,
            first.complexities,
            np.stack([m.initial for m in models]),
            np.stack([m.emission for m in models]),
            np.stack([m.transition for m in models]),
            np.arange(n, dtype=np.int64) % len(models),
        )

    @classmethod
    def dirichlet(
        cls,
        model: TrustModel,
        n: int,
        concentration: float,
        rng: np.random.Generator | int | None = 0,
        pseudo: float = 0.0,
    ) -> "Supervisors":
        """``n`` individuals drawn around a pooled ``model``: every probability row ``r`` of the
        model (initial trust, each emission row, each transition row) becomes a draw from
        Dirichlet(concentration * r + pseudo).  Larger ``concentration`` means a more homogeneous
        population; cells with zero weight (``r = 0`` and ``pseudo = 0``) stay zero."""
        _check_n(n)
        if not (np.isfinite(concentration) and concentration > 0):
            raise SimulationError([f"concentration must be a positive number, got {concentration!r}"])
        if not (np.isfinite(pseudo) and pseudo >= 0):
            raise SimulationError([f"pseudo must be a non-negative number, got {pseudo!r}"])
        rng = np.random.default_rng(rng)

        def draw(rows: np.ndarray) -> np.ndarray:
            alpha = concentration * rows + pseudo
            g = rng.gamma(np.broadcast_to(alpha, (n,) + alpha.shape))
            s = g.sum(axis=-1, keepdims=True)
            # a row whose draws all underflow to zero keeps the pooled row
            return np.where(s > 0, g / np.where(s > 0, s, 1.0), rows)

        return cls(
            model.trust_levels,
            model.complexities,
            draw(model.initial),
            draw(model.emission),
            draw(model.transition),
            np.arange(n, dtype=np.int64),
        )

    def model_of(self, participant: int) -> TrustModel:
        """The TrustModel of participant ``participant`` (0-based)."""
        p = int(self.index[participant])
        return TrustModel(self.trust_levels, self.complexities, self.initial[p], self.emission[p], self.transition[p])

    def take(self, idx: np.ndarray) -> "Supervisors":
        """The sub-population of participants ``idx`` (0-based indices)."""
        return Supervisors(self.trust_levels, self.complexities, self.initial, self.emission, self.transition, self.index[np.asarray(idx)])


def _check_n(n: int) -> None:
    if int(n) != n or n < 1:
        raise SimulationError([f"the number of participants must be a positive integer, got {n!r}"])


# --------------------------------------------------------------------------- schedules


def schedule_counts(n: int, counts: Sequence[int] | Mapping[str, int], rng, complexities: Sequence[str] = ("low", "high")) -> np.ndarray:
    """(n, T) complexity indices: each participant gets ``counts[c]`` trials of complexity ``c``
    in an independent random order (the paper: 41 low and 30 high; 17 and 17 per block)."""
    _check_n(n)
    if isinstance(counts, Mapping):
        unknown = [k for k in counts if k not in complexities]
        if unknown:
            raise SimulationError([f"unknown complexity {unknown[0]!r} in counts; expected one of {list(complexities)}"])
        counts = [int(counts.get(c, 0)) for c in complexities]
    counts = [int(k) for k in counts]
    if len(counts) != len(complexities) or any(k < 0 for k in counts) or sum(counts) < 1:
        raise SimulationError([f"counts must give a non-negative number of trials for each of {list(complexities)} "
                               f"with at least one trial in total, got {counts}"])
    # Drawing trial by trial from an urn holding the remaining trials of each complexity
    # gives every arrangement of the counts the same probability (vectorized over participants).
    rng = np.random.default_rng(rng)
    T, N = sum(counts), len(counts)
    out = np.empty((T, n), dtype=np.int8)
    remaining = [np.full(n, k, dtype=np.float64) for k in counts]
    left = T
    for t in range(T):
        x = rng.random(n)
        x *= left  # uniform over the trials left: below remaining[0] -> complexity 0, ...
        if N == 2:
            high = x >= remaining[0]
            out[t] = high
            remaining[0] -= ~high
        else:
            c = np.zeros(n, dtype=np.int8)
            edge = remaining[0].copy()
            for k in range(1, N):
                c += x >= edge
                edge += remaining[k]
            out[t] = c
            for k in range(N):
                remaining[k] -= c == k
        left -= 1
    return out.T  # (n, T), stored trial-major: the simulator reads one trial of everyone at a time


def schedule_iid(n: int, trials: int, probs: Sequence[float], rng) -> np.ndarray:
    """(n, trials) complexity indices drawn i.i.d. from ``probs`` (e.g. ``Task.complexity_probs``)."""
    _check_n(n)
    if int(trials) != trials or trials < 1:
        raise SimulationError([f"the number of trials must be a positive integer, got {trials!r}"])
    p = np.asarray(probs, dtype=float)
    u = np.random.default_rng(rng).random((int(trials), n))
    return np.searchsorted(np.cumsum(p)[:-1], u, side="right").astype(np.int8).T


# --------------------------------------------------------------------------- blocks and results


@dataclass
class Block:
    """A run of trials under one policy.

    ``schedule`` is an (n, T) array of complexity indices.  ``belief_update`` overrides the
    policy's own; ``belief_model`` is the model the robot's belief is tracked with when the
    policy has none (a complexity-only policy; the belief is then only logged).  The belief
    restarts from the model's initial trust at the start of every block; the supervisor's
    hidden trust carries over from the previous block.
    """

    policy: Any
    schedule: np.ndarray
    name: str | None = None
    belief_update: str | None = None
    belief_model: TrustModel | None = None

    @property
    def label(self) -> str:
        return self.name or self.policy.kind


@dataclass
class Simulation:
    """What a simulation produced: per-participant summaries and (when recorded) every trial."""

    task: Task
    trust_levels: tuple[str, ...]
    participant_list: np.ndarray | None  # (n,) string ids, or None for p001, p002, ...
    block_labels: list[str]
    block_lengths: list[int]
    summary_arrays: dict[str, np.ndarray]  # name -> (n, n_blocks)
    arrays: dict[str, np.ndarray] | None = None  # name -> (n, T_total), when recorded

    @property
    def n(self) -> int:
        return next(iter(self.summary_arrays.values())).shape[0]

    @property
    def participants(self) -> np.ndarray:
        """(n,) participant ids."""
        if self.participant_list is None:
            self.participant_list = participant_ids(self.n)
        return self.participant_list

    def block_of_trial(self) -> np.ndarray:
        """(T_total,) 1-based block number of every trial position."""
        return np.repeat(np.arange(1, len(self.block_lengths) + 1), self.block_lengths)

    def summary(self) -> pd.DataFrame:
        """One row per participant and block: cumulative (and discounted) reward, autonomous
        collections (autonomous successes), failures, interventions and asks."""
        n, nb = self.n, len(self.block_labels)
        out = {
            "participant": np.repeat(self.participants, nb),
            "block": np.tile(np.arange(1, nb + 1), n),
            "policy": np.tile(np.array(self.block_labels, dtype=object), n),
            "trials": np.tile(np.array(self.block_lengths), n),
        }
        for k in SUMMARY_COLUMNS[4:]:
            v = self.summary_arrays[k].reshape(-1)
            out[k] = v if k in ("cumulative_reward", "discounted_reward") else v.astype(np.int64)
        return pd.DataFrame(out, columns=list(SUMMARY_COLUMNS))

    def totals(self) -> pd.DataFrame:
        """One row per participant, summed over blocks."""
        s = self.summary()
        cols = [c for c in SUMMARY_COLUMNS[3:]]
        return s.groupby("participant", sort=False)[cols].sum().reset_index()

    def reward_matrix(self, key: str = "cumulative_reward") -> np.ndarray:
        """(n, n_blocks) array of a summary quantity."""
        return self.summary_arrays[key]

    def by_policy(self, key: str = "cumulative_reward") -> dict[str, np.ndarray]:
        """Per policy label, the (n,) values of ``key`` (summed over that policy's blocks)."""
        out: dict[str, np.ndarray] = {}
        for j, lab in enumerate(self.block_labels):
            out[lab] = out.get(lab, 0) + self.summary_arrays[key][:, j]
        return out

    def trials(self) -> pd.DataFrame:
        """Every trial in the canonical trial-log format (``participant, trial, complexity,
        robot_action, human_action, experience``) followed by ``block, policy, true_trust,
        belief, reward``."""
        if self.arrays is None:
            raise SimulationError(["this simulation did not record trials (record=False)"])
        a = self.arrays
        n, T = a["complexity"].shape
        blocks = self.block_of_trial()
        cx = np.array(self.task.complexities, dtype=object)
        tl = np.array(self.trust_levels, dtype=object)
        frame = pd.DataFrame(
            {
                "participant": np.repeat(self.participants, T),
                "trial": np.tile(np.arange(1, T + 1), n),
                "complexity": cx[a["complexity"].reshape(-1)],
                "robot_action": np.array(ACTIONS, dtype=object)[a["action"].reshape(-1)],
                "human_action": np.array(HUMAN_ACTIONS, dtype=object)[a["human"].reshape(-1)],
                "experience": np.array(EXPERIENCES, dtype=object)[a["experience"].reshape(-1)],
                "block": np.tile(blocks, n),
                "policy": np.tile(np.array(self.block_labels, dtype=object)[blocks - 1], n),
                "true_trust": tl[a["trust"].reshape(-1)],
                "belief": a["belief"].reshape(-1),
                "reward": a["reward"].reshape(-1),
            }
        )
        return frame


# --------------------------------------------------------------------------- the kernel


class _Tables:
    """Flat lookup tables for one population and task (two trust levels use scalar beliefs)."""

    def __init__(self, sup: Supervisors, task: Task):
        N, K = len(sup.complexities), sup.n_trust
        self.N, self.K = N, K
        self.pooled = sup.n_rows == 1
        self.p_int = np.ascontiguousarray(sup.emission[..., INTERVENE]).reshape(-1)  # [p, c, a, t]
        # trust transition: cumulative rows, the next trust is #(u >= cum)
        cum = np.cumsum(sup.transition, axis=-1)[..., :-1]  # [p, c, a, e, t, K-1]
        self.trust_cum = np.ascontiguousarray(cum).reshape(-1, K - 1)
        self.init_cum = np.cumsum(sup.initial, axis=-1)[:, :-1]  # [p, K-1]
        self.p_reliable = np.ascontiguousarray(task.experience_table()[..., RELIABLE]).reshape(-1)  # [c, a, o]
        self.reward = task.reward_table().reshape(-1)  # [a, o, e]
        if K == 2:
            self.trust_low = self.trust_cum[:, 0].copy()  # P(T' = low | ...)


def _policy_belief(block: Block):
    """(model, update name) of the robot's belief in a block, or (None, None)."""
    pol = block.policy
    model = pol.model or block.belief_model
    update = block.belief_update or pol.belief_update or "bayes"
    if pol.belief_update is not None and model is None:
        raise SimulationError([f"the {pol.kind} policy needs a trust model for its belief"])
    check_belief_update(update)
    return (model, update) if model is not None else (None, None)


def _run_chunk(tab: _Tables, task: Task, rows: np.ndarray, blocks: list[Block], sl: slice, seeds, record: bool, gamma: float, progress):
    m = sl.stop - sl.start
    K = tab.K
    rng_sup = np.random.default_rng(seeds[0])
    rng_pol = np.random.default_rng(seeds[1])
    two = K == 2
    # parameter-row offsets for heterogeneous populations
    poff = None if tab.pooled else rows * (2 * tab.N)
    # initial hidden trust
    u0 = rng_sup.random(m)
    icum = tab.init_cum[rows]  # (m, K-1)
    trust = (u0[:, None] >= icum).sum(axis=1).astype(np.int64)
    T_total = sum(b.schedule.shape[1] for b in blocks)
    rec = None
    if record:
        rec = {k: np.empty((T_total, m), dtype=np.int8) for k in ("complexity", "action", "human", "experience", "trust")}
        rec["belief"] = np.empty((T_total, m))
    codes = np.empty((T_total, m), dtype=np.int8)
    t_global = 0
    for block in blocks:
        sched = np.ascontiguousarray(block.schedule[sl].T).astype(np.int64)  # (T, m)
        bmodel, bupdate = _policy_belief(block)
        policy = block.policy
        scalar = None
        if bmodel is not None and bmodel.n_trust == 2:
            scalar = ScalarBelief(bmodel, bupdate)
            x = np.full(m, scalar.x0)
            B = np.empty((m, 2))
        elif bmodel is not None:
            updater = make_updater(bupdate, bmodel)
            B = np.broadcast_to(updater.initial(), (m, bmodel.n_trust)).copy()
        else:
            B = np.full((m, 2), np.nan)
        bounds = ask_bounds(policy) if scalar is not None else None
        for t in range(sched.shape[0]):
            c = sched[t]
            if bounds is not None:
                a = (x < bounds[c]).astype(np.int64)
            else:
                if scalar is not None:
                    B[:, 1] = x
                    np.subtract(1.0, x, out=B[:, 0])
                a = np.asarray(policy.actions(B, c, rng_pol), dtype=np.int64)
            u = rng_sup.random((3, m))
            ca = c * 2 + a
            cap = ca if poff is None else ca + poff
            o = (u[0] >= tab.p_int[cap * K + trust]).astype(np.int64)
            e = (u[1] < tab.p_reliable[ca * 2 + o]).astype(np.int64)
            kt = (cap * 2 + e) * K + trust
            if record:
                rec["complexity"][t_global] = c
                rec["action"][t_global] = a
                rec["human"][t_global] = o
                rec["experience"][t_global] = e
                rec["trust"][t_global] = trust
                rec["belief"][t_global] = x if scalar is not None else B[:, -1]
            codes[t_global] = (a * 2 + o) * 2 + e
            if two:
                trust = (u[2] >= tab.trust_low[kt]).astype(np.int64)
            else:
                trust = (u[2][:, None] >= tab.trust_cum[kt]).sum(axis=1)
            if scalar is not None:
                x = scalar.step(x, ca, o, e)
            elif bmodel is not None:
                B = updater.update(B, c, a, o, e)
            t_global += 1
        if progress is not None:
            progress(m * sched.shape[0])
    # summaries per block
    nb = len(blocks)
    summ = {k: np.zeros((m, nb)) for k in SUMMARY_COLUMNS[4:]}
    start = 0
    for j, block in enumerate(blocks):
        T = block.schedule.shape[1]
        cb = codes[start : start + T]
        r = tab.reward[cb]
        summ["cumulative_reward"][:, j] = r.sum(axis=0)
        summ["discounted_reward"][:, j] = gamma ** np.arange(T) @ r
        summ["autonomous_collections"][:, j] = (cb == CODE_SUCCESS).sum(axis=0)
        summ["failures"][:, j] = (cb == CODE_FAILURE).sum(axis=0)
        summ["interventions"][:, j] = (cb == CODE_INTERVENE).sum(axis=0)
        summ["asks"][:, j] = (cb >= ASK * 4).sum(axis=0)
        start += T
    out = None
    if record:
        out = {k: v.T for k, v in rec.items()}
        out["reward"] = tab.reward[codes].T
    return summ, out


def _seed_sequence(seed) -> np.random.SeedSequence:
    return seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)


def participant_ids(n: int, prefix: str = "p", start: int = 1) -> np.ndarray:
    """Ids ``p001``, ``p002``, ... (zero-padded to sort in order)."""
    width = max(3, len(str(start + n - 1)))
    return np.array([f"{prefix}{i:0{width}d}" for i in range(start, start + n)], dtype=object)


def run(
    task: Task,
    supervisors: Supervisors,
    blocks: Sequence[Block],
    seed: int | np.random.SeedSequence | None = 0,
    record: bool = True,
    participants: Sequence[str] | None = None,
    progress: Callable[[int], None] | None = None,
) -> Simulation:
    """Simulate every participant of ``supervisors`` through ``blocks`` in order.

    ``seed`` fixes every draw (supervisors' luck in chunks of :data:`CHUNK` participants, and
    the policies' own draws on a separate stream).  ``record=False`` keeps only the
    per-participant summaries (what large runs need).  ``progress(k)`` is called with the
    number of trials just simulated.
    """
    blocks = list(blocks)
    n = supervisors.n
    if not blocks:
        raise SimulationError(["a simulation needs at least one block"])
    if tuple(supervisors.complexities) != tuple(task.complexities):
        raise SimulationError([f"the supervisors' complexities {list(supervisors.complexities)} differ from the task's {list(task.complexities)}"])
    for j, b in enumerate(blocks):
        sch = np.asarray(b.schedule)
        if sch.ndim != 2 or sch.shape[0] != n or sch.shape[1] < 1:
            raise SimulationError([f"block {j + 1}: schedule has shape {sch.shape}, expected ({n}, trials)"])
        if sch.min() < 0 or sch.max() >= task.n_complexity:
            raise SimulationError([f"block {j + 1}: schedule holds complexity indices outside 0..{task.n_complexity - 1}"])
        if tuple(getattr(b.policy, "complexities", task.complexities)) != tuple(task.complexities):
            raise SimulationError([f"block {j + 1}: the policy's complexities {list(b.policy.complexities)} differ from the task's {list(task.complexities)}"])
        bm = getattr(b.policy, "model", None) or b.belief_model
        if bm is not None and tuple(bm.complexities) != tuple(task.complexities):
            raise SimulationError([f"block {j + 1}: the belief model's complexities differ from the task's"])
        b.schedule = sch
        _policy_belief(b)
    if participants is not None:
        participants = np.asarray(participants, dtype=object)
        if len(participants) != n:
            raise SimulationError([f"{len(participants)} participant ids for {n} participants"])
    tab = _Tables(supervisors, task)
    ss = _seed_sequence(seed)
    n_chunks = -(-n // CHUNK)
    chunk_seeds = [s.spawn(2) for s in ss.spawn(n_chunks)]
    nb = len(blocks)
    summary = {k: np.zeros((n, nb)) for k in SUMMARY_COLUMNS[4:]}
    T_total = sum(b.schedule.shape[1] for b in blocks)
    arrays = None
    if record:
        arrays = {k: np.empty((n, T_total), dtype=np.int8) for k in ("complexity", "action", "human", "experience", "trust")}
        arrays["belief"] = np.empty((n, T_total))
        arrays["reward"] = np.empty((n, T_total))
    for i in range(n_chunks):
        sl = slice(i * CHUNK, min(n, (i + 1) * CHUNK))
        summ, rec = _run_chunk(tab, task, supervisors.index[sl], blocks, sl, chunk_seeds[i], record, task.discount, progress)
        for k, v in summ.items():
            summary[k][sl] = v
        if record:
            for k, v in rec.items():
                arrays[k][sl] = v
    return Simulation(
        task=task,
        trust_levels=tuple(supervisors.trust_levels),
        participant_list=participants,
        block_labels=[b.label for b in blocks],
        block_lengths=[b.schedule.shape[1] for b in blocks],
        summary_arrays=summary,
        arrays=arrays,
    )


# --------------------------------------------------------------------------- convenience


def simulate(
    model: TrustModel | Supervisors,
    task: Task,
    policy,
    n_participants: int = 1,
    counts: Sequence[int] | Mapping[str, int] | None = None,
    trials: int | None = None,
    seed: int = 0,
    record: bool = True,
    belief_update: str | None = None,
    belief_model: TrustModel | None = None,
    progress: Callable[[int], None] | None = None,
) -> Simulation:
    """One block per participant under ``policy``.

    The trial sequence is either ``counts`` trials of each complexity in random order or
    ``trials`` i.i.d. complexities from ``task.complexity_probs``.  ``model`` is a pooled
    TrustModel or a :class:`Supervisors` population (then ``n_participants`` is its size).
    """
    sup = model if isinstance(model, Supervisors) else Supervisors.pooled(model, n_participants)
    ss = _seed_sequence(seed)
    s_sched, s_run = ss.spawn(2)
    if (counts is None) == (trials is None):
        raise SimulationError(["give either counts (trials per complexity, in random order) or trials (i.i.d. complexities)"])
    if counts is not None:
        sched = schedule_counts(sup.n, counts, np.random.default_rng(s_sched), task.complexities)
    else:
        sched = schedule_iid(sup.n, trials, task.complexity_probs, np.random.default_rng(s_sched))
    block = Block(policy, sched, belief_update=belief_update, belief_model=belief_model)
    return run(task, sup, [block], seed=s_run, record=record, progress=progress)


def crossover(
    model: TrustModel | Supervisors,
    task: Task,
    policies: Sequence[Any],
    n_participants: int,
    counts: Sequence[int] | Mapping[str, int] = PAPER_BLOCK_COUNTS,
    first: Sequence[int] | None = None,
    seed: int = 0,
    record: bool = True,
    belief_model: TrustModel | None = None,
    progress: Callable[[int], None] | None = None,
) -> Simulation:
    """The within-participant design of Section VI-B: every participant does one block per
    policy (``counts`` trials of each complexity in random order, per block), in an order that
    is counterbalanced across participants.

    ``first[i]`` is the index of the policy participant ``i`` starts with; by default
    participants take the policies' rotations in turn (with two policies and five
    participants: 3 start with the first policy, 2 with the second, as in the paper).  Blocks
    are labelled by policy, so ``by_policy`` gives paired values per participant; the
    ``block`` column of the trials is the position (1 = first block done).
    """
    sup = model if isinstance(model, Supervisors) else Supervisors.pooled(model, n_participants)
    n = sup.n
    P = len(policies)
    if P < 1:
        raise SimulationError(["crossover needs at least one policy"])
    first = np.arange(n) % P if first is None else np.asarray(first, dtype=np.int64)
    if first.shape != (n,) or first.min() < 0 or first.max() >= P:
        raise SimulationError([f"first must give, for each of the {n} participants, a policy index in 0..{P - 1}"])
    ss = _seed_sequence(seed)
    s_sched, s_run = ss.spawn(2)
    rs = np.random.default_rng(s_sched)
    scheds = [schedule_counts(n, counts, rs, task.complexities) for _ in range(P)]
    labels = [getattr(p, "kind", f"policy {j + 1}") for j, p in enumerate(policies)]
    if len(set(labels)) != len(labels):
        labels = [f"{lab} {j + 1}" for j, lab in enumerate(labels)]
    ids = participant_ids(n)
    # one run per starting policy; participant streams come from one seed per order group
    group_seeds = s_run.spawn(P)
    parts = []
    for g in range(P):
        idx = np.flatnonzero(first == g)
        if len(idx) == 0:
            continue
        order = [(g + k) % P for k in range(P)]
        blocks = [Block(policies[j], scheds[k][idx], name=labels[j], belief_model=belief_model) for k, j in enumerate(order)]
        sim = run(task, sup.take(idx), blocks, seed=group_seeds[g], record=record, participants=ids[idx], progress=progress)
        parts.append((idx, order, sim))
    return _merge_crossover(task, sup, ids, labels, parts, record)


def _merge_crossover(task, sup, ids, labels, parts, record) -> Simulation:
    n, P = len(ids), len(labels)
    summary = {k: np.zeros((n, P)) for k in SUMMARY_COLUMNS[4:]}
    arrays = None
    lengths = None
    orders = np.zeros((n, P), dtype=np.int64)
    for idx, order, sim in parts:
        for k in summary:
            summary[k][idx[:, None], np.array(order)[None, :]] = sim.summary_arrays[k]
        orders[idx] = order
        if record:
            if arrays is None:
                T = sim.arrays["complexity"].shape[1]
                arrays = {k: np.empty((n, T), dtype=v.dtype) for k, v in sim.arrays.items()}
            for k, v in sim.arrays.items():
                arrays[k][idx] = v
        lengths = sim.block_lengths
    out = CrossoverSimulation(
        task=task,
        trust_levels=tuple(sup.trust_levels),
        participant_list=ids,
        block_labels=list(labels),
        block_lengths=list(lengths),
        summary_arrays=summary,
        arrays=arrays,
    )
    out.orders = orders
    return out


@dataclass
class CrossoverSimulation(Simulation):
    """A :class:`Simulation` whose summary columns are per policy (not per position); ``orders[i]``
    lists the policy indices in the order participant ``i`` met them."""

    orders: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=np.int64))

    def summary(self) -> pd.DataFrame:
        s = super().summary()
        pos = np.argsort(self.orders, axis=1) + 1  # position of each policy for each participant
        s["block"] = pos.reshape(-1)
        return s

    def trials(self) -> pd.DataFrame:
        frame = super().trials()
        n, P = self.orders.shape
        T = frame.shape[0] // max(n, 1)
        lab = np.array(self.block_labels, dtype=object)
        pos = self.block_of_trial() - 1  # position of each trial (blocks have equal lengths)
        frame["policy"] = lab[self.orders[:, pos]].reshape(-1)
        return frame


def summarize(values: Mapping[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """Median, mean and quartiles of per-participant values, per policy label."""
    out = {}
    for k, v in values.items():
        v = np.asarray(v, dtype=float)
        out[k] = {
            "n": int(len(v)),
            "median": float(np.median(v)),
            "mean": float(np.mean(v)),
            "q1": float(np.percentile(v, 25)),
            "q3": float(np.percentile(v, 75)),
            "sd": float(np.std(v, ddof=1)) if len(v) > 1 else 0.0,
        }
    return out
