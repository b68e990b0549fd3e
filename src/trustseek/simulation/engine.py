"""Simulated supervisors: a vectorized Monte-Carlo model of the object-collection task.

Each simulated participant is a supervisor drawn from a :class:`~trustseek.model.TrustModel` who
works through one or more blocks of trials, each under one robot policy.  Trial ``t`` follows
Sections III-IV: the complexity ``C_t`` comes from the schedule; the robot picks ``a_t`` from its
belief; ``o_t ~ P(o | T_t, C_t, a_t)``; ``E_{t+1} ~ P(E | o_t, C_t, a_t)``; the reward is eq. (1);
``T_{t+1} ~ P(T' | T_t, E_{t+1}, C_t, a_t)`` and the robot updates its belief (``paper``/``bayes``).

All participants advance together, one trial at a time (in chunks of :data:`CHUNK`).  Every trial
draws the same three uniforms per participant whatever the robot does, from a generator separate
from the policy's, so runs with the same seed and different policies face the same supervisors,
schedules and luck (common random numbers).  The common cases (two trust levels; a threshold
policy on the scalar belief, or fixed ask probabilities per complexity) run in the compiled loop
of :mod:`.kernels` (built with the package), which gives the same simulation to the last bit;
``compiled=False`` runs the numpy loop for every block.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..model.core import TrustModel
from ..model.task import Task
from ..policies.base import Policy, PolicyError, ask_bounds
from ..policies.complexity import ComplexityPolicy
from ..policies.runner import PolicyRunner
from ..pomdp.belief import ScalarBelief
from ..seeds import seed_sequence
from ..vocab import ASK, AUTONOMOUS, INTERVENE, RELIABLE, RELY, check_belief_update
from . import kernels
from .populations import SimulationError, Supervisors
from .results import SUMMARY_QUANTITIES, Simulation
from .trial_orders import schedule_counts, schedule_iid

CHUNK = 1 << 14  # participants simulated together (fits the working set in cache)
WINDOW = 1 << 15  # trials x participants whose uniforms the compiled kernel draws at once

# outcome code of a trial: (a * 2 + o) * 2 + e
CODE_INTERVENE = (AUTONOMOUS * 2 + INTERVENE) * 2 + 0
CODE_FAILURE = (AUTONOMOUS * 2 + RELY) * 2 + 0
CODE_SUCCESS = (AUTONOMOUS * 2 + RELY) * 2 + RELIABLE


@dataclass
class Block:
    """A run of trials under one policy.

    ``schedule`` is an (n, T) array of complexity indices.  ``belief_update`` overrides the
    policy's own; ``belief_model`` is the model the robot's belief is tracked with when the
    policy has none (a complexity-only policy; the belief is then only logged).  The belief
    restarts from the model's initial trust at the start of every block; the supervisor's
    hidden trust carries over from the previous block.
    """

    policy: Policy
    schedule: np.ndarray
    name: str | None = None
    belief_update: str | None = None
    belief_model: TrustModel | None = None

    @property
    def label(self) -> str:
        return self.name or self.policy.kind


# --------------------------------------------------------------------------- the kernel


class Tables:
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

    def trial(
        self, u: np.ndarray, ca: np.ndarray, cap: np.ndarray, trust: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One trial of every participant from its three uniforms ``u`` (3, m), with ``ca`` = c * 2 + a
        (``cap``: plus the participants' parameter-row offsets) and the hidden ``trust``: the human
        action, the experience and the next hidden trust."""
        K = self.K
        o = (u[0] >= self.p_int[cap * K + trust]).astype(np.int64)
        e = (u[1] < self.p_reliable[ca * 2 + o]).astype(np.int64)
        kt = (cap * 2 + e) * K + trust
        # the next hidden trust: below P(T' = low) for two levels, #(u >= cumulative row) otherwise
        if K == 2:
            return o, e, (u[2] >= self.trust_low[kt]).astype(np.int64)
        return o, e, (u[2][:, None] >= self.trust_cum[kt]).sum(axis=1)


def _runner(block: Block) -> PolicyRunner:
    """The block's policy with the robot's belief: tracked with the policy's own model, else the
    block's belief model (then only logged), updated by the block's update, else the policy's,
    else ``bayes``."""
    pol = block.policy
    try:
        runner = PolicyRunner(pol, model=pol.model or block.belief_model, belief_update=block.belief_update)
    except PolicyError:
        raise SimulationError([f"the {pol.kind} policy needs a trust model for its belief"]) from None
    check_belief_update(runner.belief_update)
    return runner


RECORDED = ("complexity", "action", "human", "experience", "trust")  # int8 arrays of a recorded run


def _records(shape: tuple[int, int]) -> dict[str, np.ndarray]:
    """Arrays of ``shape`` for what a recorded run keeps of each trial: :data:`RECORDED` and the belief."""
    return {k: np.empty(shape, dtype=np.int8) for k in RECORDED} | {"belief": np.empty(shape)}


def _compiled_action(policy: Policy, bounds: np.ndarray | None, scalar: bool) -> tuple[int, np.ndarray] | None:
    """How the compiled block chooses the robot's action under ``policy``: (THRESHOLD, bounds)
    on a scalar belief, (FIXED, p_ask) for a complexity policy; None when only the numpy loop
    can run it (``scalar``: the belief, if any, is a scalar one)."""
    if not scalar:
        return None
    if bounds is not None:
        return kernels.THRESHOLD, np.ascontiguousarray(bounds, dtype=np.float64)
    if type(policy) is ComplexityPolicy:
        return kernels.FIXED, np.ascontiguousarray(policy.p_ask, dtype=np.float64)
    return None


_EMPTY = np.zeros(0)


def _run_chunk(
    tab: Tables,
    rows: np.ndarray,
    blocks: list[Block],
    sl: slice,
    seeds: Sequence[np.random.SeedSequence],
    record: bool,
    gamma: float,
    progress: Callable[[int], None] | None,
    compiled: bool = True,
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Participants ``sl`` (parameter rows ``rows``) through every block, each in the compiled
    kernel when ``compiled`` and it can, else in the numpy loop: the per-block summaries and,
    when ``record``, every trial (participant-major arrays)."""
    st = _Chunk(tab, rows, sl, seeds, record, sum(b.schedule.shape[1] for b in blocks))
    for block in blocks:
        sched = np.ascontiguousarray(block.schedule[sl].T).astype(np.int64)  # (T, m)
        runner = _runner(block)
        scalar, x, B, tracked = _belief_start(runner, st.m)
        bounds = ask_bounds(block.policy) if scalar is not None else None
        fast = _compiled_action(block.policy, bounds, not tracked) if compiled and tab.K == 2 else None
        if fast is not None:
            _compiled_block(st, sched, fast, scalar, x)
        else:
            _numpy_block(st, sched, runner, scalar, x, B, bounds, tracked)
        if progress is not None:
            progress(st.m * sched.shape[0])
    summ = _summaries(tab, blocks, st.codes, gamma, st.m)
    out: dict[str, np.ndarray] = {}
    if record:
        out = {k: v.T for k, v in st.rec.items()}
        out["reward"] = tab.reward[st.codes].T
    return summ, out


class _Chunk:
    """The state of a chunk of participants across its blocks: the random streams, the hidden
    trust (it carries over from block to block), the trials' codes and, when ``record``, every trial."""

    def __init__(
        self, tab: Tables, rows: np.ndarray, sl: slice, seeds: Sequence[np.random.SeedSequence], record: bool, total: int
    ) -> None:
        self.tab, self.record = tab, record
        self.m = m = sl.stop - sl.start
        self.rng_sup = np.random.default_rng(seeds[0])
        self.rng_pol = np.random.default_rng(seeds[1])
        self.poff = None if tab.pooled else rows * (2 * tab.N)  # parameter-row offsets for heterogeneous populations
        u0 = self.rng_sup.random(m)  # the initial hidden trust
        self.trust = (u0[:, None] >= tab.init_cum[rows]).sum(axis=1).astype(np.int64)
        self.rec = _records((total, m)) if record else {}
        self.codes = np.empty((total, m), dtype=np.int8)
        self.t = 0  # the next trial of the chunk


def _belief_start(runner: PolicyRunner, m: int) -> tuple[ScalarBelief | None, np.ndarray, np.ndarray, bool]:
    """The robot's belief at the start of a block: the scalar filter on P(trust = high) with its
    start ``x`` for two trust levels, else the runner's beliefs ``B`` (tracked row by row for
    more levels; NaN when the policy has no belief)."""
    model = runner.model
    if model is not None and model.n_trust == 2:
        scalar = ScalarBelief(model, runner.belief_update or "bayes")  # the same filter on P(trust = high)
        return scalar, np.full(m, scalar.x0), np.empty((m, 2)), False
    b0 = runner.initial_beliefs(m)
    tracked = model is not None and model.n_trust > 2  # the runner's own filter, row by row
    return None, _EMPTY, np.full((m, 2), np.nan) if b0 is None else b0, tracked


def _compiled_block(
    st: _Chunk, sched: np.ndarray, fast: tuple[int, np.ndarray], scalar: ScalarBelief | None, x: np.ndarray
) -> None:
    """A block in the compiled kernel, ``span`` trials of uniforms at a time (the same draws as the numpy loop)."""
    tab, m, T = st.tab, st.m, sched.shape[0]
    mode, act = fast
    if mode == kernels.FIXED:
        pv = act[sched]
        draws = ~np.all((pv == 0) | (pv == 1), axis=1)  # the trials where actions() draws
    else:
        draws = np.zeros(T, dtype=bool)
    if scalar is not None:
        bel = kernels.BAYES if scalar.update_name == "bayes" else kernels.PAPER
        sb = (scalar.a0, scalar.slope, scalar.lik_high, scalar.lik_low)
    else:
        bel, sb, x = kernels.NO_BELIEF, (_EMPTY,) * 4, np.zeros(m)
    into = st.rec if st.record else _records((0, 0))
    offsets = np.zeros(m, dtype=np.int64) if st.poff is None else st.poff.astype(np.int64)
    tables = (tab.p_int, tab.p_reliable, tab.trust_low, offsets)
    records = (st.record, *(into[k] for k in (*RECORDED, "belief")))
    span = max(1, WINDOW // m)
    for t0 in range(0, T, span):  # the uniforms of ``span`` trials at a time
        t1 = min(T, t0 + span)
        upol = st.rng_pol.random((int(draws[t0:t1].sum()), m))  # = one random(m) per trial that draws
        u = st.rng_sup.random((t1 - t0, 3, m))  # = successive random((3, m))
        kernels.run_block(
            sched[t0:t1], (u, upol, draws[t0:t1]), fast, (bel, *sb), x, tables, st.trust, st.codes, st.t + t0, records
        )
    st.t += T


def _numpy_block(
    st: _Chunk,
    sched: np.ndarray,
    runner: PolicyRunner,
    scalar: ScalarBelief | None,
    x: np.ndarray,
    B: np.ndarray,
    bounds: np.ndarray | None,
    tracked: bool,
) -> None:
    """A block in the numpy loop, one trial of every participant at a time."""
    tab = st.tab
    for c in sched:
        if bounds is not None:
            a = (x < bounds[c]).astype(np.int64)
        else:
            if scalar is not None:
                B[:, 1] = x
                np.subtract(1.0, x, out=B[:, 0])
            a = runner.actions_many(B, c, st.rng_pol)
        u = st.rng_sup.random((3, st.m))
        ca = c * 2 + a
        cap = ca if st.poff is None else ca + st.poff
        o, e, trust = tab.trial(u, ca, cap, st.trust)
        if st.record:
            for k, v in zip((*RECORDED, "belief"), (c, a, o, e, st.trust, x if scalar is not None else B[:, -1]), strict=True):
                st.rec[k][st.t] = v
        st.codes[st.t] = (a * 2 + o) * 2 + e
        st.trust = trust
        if scalar is not None:
            x = scalar.step(x, ca, o, e)
        elif tracked:
            B = runner.beliefs_after_many(B, c, a, o, e)
        st.t += 1


def _summaries(tab: Tables, blocks: list[Block], codes: np.ndarray, gamma: float, m: int) -> dict[str, np.ndarray]:
    """The per-block summaries of every participant, from the trials' codes."""
    summ = {k: np.zeros((m, len(blocks))) for k in SUMMARY_QUANTITIES}
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
    return summ


def run(
    task: Task,
    supervisors: Supervisors,
    blocks: Sequence[Block],
    seed: int | np.random.SeedSequence | None = 0,
    record: bool = True,
    participants: Sequence[str] | np.ndarray | None = None,
    progress: Callable[[int], None] | None = None,
    compiled: bool = True,
) -> Simulation:
    """Simulate every participant of ``supervisors`` through ``blocks`` in order.

    ``seed`` fixes every draw (the supervisors' per chunk of :data:`CHUNK` participants, the
    policies' on a separate stream).  ``record=False`` keeps only the per-participant summaries.
    ``progress(k)`` is called with the number of trials just simulated.  ``compiled=False`` runs
    every block in the numpy loop (the reference of the compiled kernel; the same simulation).
    """
    blocks = list(blocks)
    n = supervisors.n
    if not blocks:
        raise SimulationError(["a simulation needs at least one block"])
    if tuple(supervisors.complexities) != tuple(task.complexities):
        raise SimulationError(
            [f"the supervisors' complexities {list(supervisors.complexities)} differ from the task's {list(task.complexities)}"]
        )
    for j, b in enumerate(blocks):
        _check_block(j, b, n, task)
    ids = None
    if participants is not None:
        ids = np.asarray(participants, dtype=object)
        if len(ids) != n:
            raise SimulationError([f"{len(ids)} participant ids for {n} participants"])
    tab = Tables(supervisors, task)
    ss = seed_sequence(seed)
    n_chunks = -(-n // CHUNK)
    chunk_seeds = [s.spawn(2) for s in ss.spawn(n_chunks)]
    nb = len(blocks)
    summary = {k: np.zeros((n, nb)) for k in SUMMARY_QUANTITIES}
    T_total = sum(b.schedule.shape[1] for b in blocks)
    arrays = _records((n, T_total)) | {"reward": np.empty((n, T_total))} if record else {}
    for i in range(n_chunks):
        sl = slice(i * CHUNK, min(n, (i + 1) * CHUNK))
        summ, rec = _run_chunk(tab, supervisors.index[sl], blocks, sl, chunk_seeds[i], record, task.discount, progress, compiled)
        for k, v in summ.items():
            summary[k][sl] = v
        for k, v in rec.items():
            arrays[k][sl] = v
    return Simulation(
        task=task,
        trust_levels=tuple(supervisors.trust_levels),
        participant_list=ids,
        block_labels=[b.label for b in blocks],
        block_lengths=[b.schedule.shape[1] for b in blocks],
        summary_arrays=summary,
        arrays=arrays if record else None,
    )


def _check_block(j: int, b: Block, n: int, task: Task) -> None:
    """Refuse block ``j`` unless its schedule, policy and belief model fit ``n`` participants
    and ``task``; stores the schedule as an array."""
    sch = np.asarray(b.schedule)
    if sch.ndim != 2 or sch.shape[0] != n or sch.shape[1] < 1:
        raise SimulationError([f"block {j + 1}: schedule has shape {sch.shape}, expected ({n}, trials)"])
    if sch.min() < 0 or sch.max() >= task.n_complexity:
        raise SimulationError([f"block {j + 1}: schedule holds complexity indices outside 0..{task.n_complexity - 1}"])
    if tuple(getattr(b.policy, "complexities", task.complexities)) != tuple(task.complexities):
        raise SimulationError(
            [
                f"block {j + 1}: the policy's complexities {list(b.policy.complexities)} "
                f"differ from the task's {list(task.complexities)}"
            ]
        )
    bm = getattr(b.policy, "model", None) or b.belief_model
    if bm is not None and tuple(bm.complexities) != tuple(task.complexities):
        raise SimulationError([f"block {j + 1}: the belief model's complexities differ from the task's"])
    b.schedule = sch
    _runner(b)


def simulate(
    model: TrustModel | Supervisors,
    task: Task,
    policy: Policy,
    n_participants: int = 1,
    counts: Sequence[int] | Mapping[str, int] | None = None,
    trials: int | None = None,
    seed: int | np.random.SeedSequence = 0,
    record: bool = True,
    belief_model: TrustModel | None = None,
    compiled: bool = True,
) -> Simulation:
    """One block per participant under ``policy``.

    The trial sequence is either ``counts`` trials of each complexity in random order or
    ``trials`` i.i.d. complexities from ``task.complexity_probs``.  ``model`` is a pooled
    TrustModel or a :class:`Supervisors` population (then ``n_participants`` is its size).
    ``compiled`` as in :func:`run`.
    """
    sup = model if isinstance(model, Supervisors) else Supervisors.pooled(model, n_participants)
    ss = seed_sequence(seed)
    s_sched, s_run = ss.spawn(2)
    if counts is not None and trials is None:
        sched = schedule_counts(sup.n, counts, np.random.default_rng(s_sched), task.complexities, compiled=compiled)
    elif trials is not None and counts is None:
        sched = schedule_iid(sup.n, trials, task.complexity_probs, np.random.default_rng(s_sched))
    else:
        raise SimulationError(["give either counts (trials per complexity, in random order) or trials (i.i.d. complexities)"])
    block = Block(policy, sched, belief_model=belief_model)
    return run(task, sup, [block], seed=s_run, record=record, compiled=compiled)
