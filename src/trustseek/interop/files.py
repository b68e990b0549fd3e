"""Standard POMDP files: Cassandra's ``.pomdp`` format and POMDPX.

Files are read into and written from a :class:`~trustseek.pomdp.flat.FlatPOMDP` (a plain
discrete POMDP).  :func:`read_pomdp` / :func:`write_pomdp` handle Cassandra's format
(``T:``, ``O:``, ``R:`` entries with names or indices, ``*`` wildcards, rows,
matrices, ``uniform`` and ``identity``), so benchmark files such as Tiger can be
solved with the point-based solver and checked against published values.

Both writers follow the published formats so that other tools (pomdp-solve, SARSOP) load the
files unpatched: ``.pomdp`` names are identifiers ``[a-zA-Z][a-zA-Z0-9_-]*`` (state names join
their parts with ``_``), numbers are positional with a digit on each side of the point; the
POMDPX file respects the mixed-observability rules of POMDPX 1.0 (see :func:`write_pomdpx`).

Exporting the assistance POMDP (:func:`flat_from_assistance`).  In the paper
the human action o_t depends on the state at the START of trial t, while a
file's observation depends on the next state.  The export therefore augments the
state with the last human action: a flat state is (T, E, C, last human action),
and one step draws the human action together with the next trust and experience
from the joint kernel P(o, E', T' | T, C, a) and the next complexity from P(C):

    s = (T, E, C, ·)  --a-->  s' = (T', E', C', o)   with probability P(C') P(o, E', T' | T, C, a).

The observation is (o, E', C'), read off s' with probability one: the human
action of the trial just played and the experience and complexity that the robot
sees.  The reward of (s, a) is eq. (2).  A belief over trust b with a known
complexity c maps to the flat belief b(T) on (T, E = reliable, C = c, last = rely);
the finite-horizon values of the two problems then agree exactly for every
horizon (the tests check this against pomdp-py).  The ``start`` line of the file
is P(T_1) P(C) with E = reliable: a flat solver does not observe the first
complexity before the first action, so its value at ``start`` is a lower bound
on Σ_C P(C) V(b0, C); start from one complexity (``initial_complexity``) to
compare values.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from itertools import product
from pathlib import Path
from typing import Any

import numpy as np

from ..model.jsonfile import read_text
from ..pomdp.belief import to_vector
from ..pomdp.flat import FlatPOMDP, FlatPOMDPError
from ..pomdp.problem import AssistancePOMDP
from ..vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS


class PomdpFileError(FlatPOMDPError):
    """A ``.pomdp`` or POMDPX file is malformed."""


# --------------------------------------------------------------------------- export of the assistance POMDP


# Cassandra's grammar: an identifier is [a-zA-Z][a-zA-Z0-9_-]* and is not one of its keywords.
# POMDPX value names are XML tokens; the same identifiers are used there, so one name works in both.
_IDENT = re.compile(r"[A-Za-z][A-Za-z0-9_\-]*")
_HEADER = ("discount", "values", "states", "actions", "observations", "start")
_CASSANDRA_KEYWORDS = frozenset((*_HEADER, "T", "O", "R", "uniform", "identity", "reward", "cost", "include", "exclude", "reset"))


def _token(name: str) -> str:
    """``name`` made into an identifier: other characters become ``_``, a leading non-letter gets ``v``."""
    tok = re.sub(r"[^A-Za-z0-9_\-]", "_", name)
    if not tok[:1].isalpha() or not tok[:1].isascii():
        tok = "v" + tok
    return tok + "_" if tok in _CASSANDRA_KEYWORDS else tok


def _tokens(names: Sequence[str]) -> list[str]:
    """Distinct identifiers for ``names`` (a position suffix where two would coincide)."""
    toks = [_token(n) for n in names]
    if len(set(toks)) < len(toks):
        toks = [f"{t}_{i}" for i, t in enumerate(toks)]
    return toks


def flat_from_assistance(pomdp: AssistancePOMDP, initial_complexity: int | None = None) -> FlatPOMDP:
    """The flat POMDP with states (T, E, C, last human action) -- see the module docstring."""
    K, N = pomdp.n_trust, pomdp.n_complexity
    kern = pomdp.kernel  # [c, a, t, o, e, u]
    pc = pomdp.complexity_probs
    T_, C_ = _tokens(pomdp.trust_levels), _tokens(pomdp.complexities)
    cells = product(range(K), range(2), range(N), range(2))
    states = _tokens([f"{T_[t]}_{EXPERIENCES[e]}_{C_[c]}_{HUMAN_ACTIONS[o]}" for t, e, c, o in cells])
    obs = _tokens([f"{HUMAN_ACTIONS[o]}_{EXPERIENCES[e]}_{C_[c]}" for o in range(2) for e in range(2) for c in range(N)])

    n_s, n_o = len(states), len(obs)
    Tm = np.zeros((2, n_s, n_s))
    Om = np.zeros((2, n_s, n_o))
    Rm = np.zeros((2, n_s, n_s, n_o))
    R = pomdp.expected_reward  # [c, a, t]
    for a in range(2):
        for t, e, c, o in product(range(K), range(2), range(N), range(2)):
            s = _state_index(t, e, c, o, N)
            Om[a, s, (o * 2 + e) * N + c] = 1.0  # observation (o, e, c)
            Rm[a, s] = R[c, a, t]
            for o2, e2, u, c2 in product(range(2), range(2), range(K), range(N)):
                Tm[a, s, _state_index(u, e2, c2, o2, N)] += pc[c2] * kern[c, a, t, o2, e2, u]
    start = np.zeros(n_s)
    cw = pc if initial_complexity is None else np.eye(N)[initial_complexity]
    for t, c in product(range(K), range(N)):
        start[_state_index(t, 1, c, 1, N)] = pomdp.model.initial[t] * cw[c]
    notes = [
        "trustseek assistance POMDP, flat form",
        "state names: <trust>_<experience>_<complexity>_<last human action>; "
        "observation names: <human action>_<experience>_<complexity>",
        "the human action of a trial depends on the trust at its start: it is drawn with the transition and "
        "stored in the next state, then observed",
    ]
    return FlatPOMDP(tuple(states), ACTIONS, tuple(obs), Tm, Om, Rm, pomdp.discount, start, notes)


def flat_belief(pomdp: AssistancePOMDP, belief, complexity: int) -> np.ndarray:
    """The flat belief for a belief over trust and a known complexity (E = reliable, last = rely)."""
    K, N = pomdp.n_trust, pomdp.n_complexity
    out = np.zeros(K * 2 * N * 2)
    out[[_state_index(t, 1, complexity, 1, N) for t in range(K)]] = to_vector(belief, K)
    return out


def _state_index(t: int, e: int, c: int, o: int, n_complexity: int) -> int:
    """The flat state (T, E, C, last human action) in the export's order."""
    return ((t * 2 + e) * n_complexity + c) * 2 + o


# --------------------------------------------------------------------------- Cassandra .pomdp


def _num(x: float) -> str:
    """A number as both formats accept it: positional, with at least one digit on each side of
    the point (Cassandra's rule), never an exponent; the shortest text that reads back exactly."""
    s = np.format_float_positional(float(x), unique=True, trim="0")
    return "0.0" if s == "-0.0" else s


def _names_or_count(names: Sequence[str]) -> tuple[str, list[str]]:
    """The header text for a list of names and how entries refer to each element: the names when
    they are identifiers, the count and indices when they are the default names 0..n-1, otherwise
    identifiers made from the names."""
    names = list(names)
    if all(_IDENT.fullmatch(n) and n not in _CASSANDRA_KEYWORDS for n in names) and len(set(names)) == len(names):
        return " ".join(names), names
    if names == [str(i) for i in range(len(names))]:
        return str(len(names)), names
    toks = _tokens(names)
    return " ".join(toks), toks


def write_pomdp(flat: FlatPOMDP, path: str | Path | None = None) -> str:
    """Write Cassandra's ``.pomdp`` format (its published grammar: the preamble, ``start:``, then the
    ``T:``, ``O:`` and ``R:`` entries); returns the text (and writes it when ``path`` is given)."""
    state_header, states = _names_or_count(flat.states)
    action_header, actions = _names_or_count(flat.actions)
    obs_header, observations = _names_or_count(flat.observations)
    lines = [f"# {n}" for note in flat.notes for n in str(note).splitlines()]
    lines += [
        f"discount: {_num(flat.discount)}",
        "values: reward",
        "states: " + state_header,
        "actions: " + action_header,
        "observations: " + obs_header,
        "start: " + " ".join(_num(x) for x in flat.start),
        "",
    ]
    for key, table in (("T", flat.transition), ("O", flat.observation)):
        for a, an in enumerate(actions):
            lines += [f"{key}: {an}", *(" ".join(_num(x) for x in row) for row in table[a]), ""]
    for a, an in enumerate(actions):
        for s, sn in enumerate(states):
            block = flat.reward[a, s]
            if np.all(block == block.flat[0]):
                if block.flat[0] != 0:
                    lines.append(f"R: {an} : {sn} : * : * {_num(block.flat[0])}")
                continue
            for s2, o in zip(*np.nonzero(block), strict=True):
                lines.append(f"R: {an} : {sn} : {states[s2]} : {observations[o]} {_num(block[s2, o])}")
    return _written("\n".join(lines) + "\n", path)


def read_pomdp(source: str | Path, text: str | None = None) -> FlatPOMDP:
    """Parse Cassandra's ``.pomdp`` format from a file (or from ``text``, with ``source`` as its label)."""
    label = str(source)
    if text is None:
        text = read_text(source, ".pomdp", PomdpFileError)
    r = _PomdpReader(label, _entries(text, label))
    start = r.start()
    n_a, n_s, n_o = len(r.actions), len(r.states), len(r.observations)
    tables = {"T": np.zeros((n_a, n_s, n_s)), "O": np.zeros((n_a, n_s, n_o)), "R": np.zeros((n_a, n_s, n_s, n_o))}
    for no, k, rest in r.groups:
        if k in tables:
            r.entry(tables[k], k, no, rest)
    try:
        return FlatPOMDP(r.states, r.actions, r.observations, tables["T"], tables["O"], tables["R"], r.discount, start)
    except FlatPOMDPError as exc:
        raise PomdpFileError(exc.problems, label) from None


_KEY = re.compile(r"^\s*(discount|values|states|actions|observations|start\s+include|start\s+exclude|start|T|O|R)\s*:(.*)$")


def _entries(text: str, label: str) -> list[tuple[int, str, str]]:
    """The lines grouped into entries ``(line, keyword, rest)``: an entry starts with a keyword followed by ':'."""
    groups: list[tuple[int, str, str]] = []
    for no, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].rstrip()
        if not line.strip():
            continue
        m = _KEY.match(line)
        if m:
            groups.append((no, re.sub(r"\s+", " ", m.group(1)), m.group(2)))
        elif groups:
            n0, k, rest = groups[-1]
            groups[-1] = (n0, k, rest + " " + line)
        else:
            raise PomdpFileError([f"line {no}: expected a header such as 'states:', got {line.strip()!r}"], label)
    return groups


class _PomdpReader:
    """The sections of a ``.pomdp`` file: the preamble (names, discount, values), ``start`` and
    the ``T:``, ``O:`` and ``R:`` entries, each problem reported with its line."""

    def __init__(self, label: str, groups: list[tuple[int, str, str]]) -> None:
        self.label, self.groups = label, groups
        self.header = {k: (no, rest.strip()) for no, k, rest in groups if k in _HEADER or k.startswith("start")}
        self.states, self.actions, self.observations = self.names("states"), self.names("actions"), self.names("observations")
        self.discount, self.sign = self._discount(), self._sign()

    def error(self, line: str) -> PomdpFileError:
        return PomdpFileError([line], self.label)

    def need(self, k: str) -> tuple[int, str]:
        if k not in self.header:
            raise self.error(f"missing '{k}:' header")
        return self.header[k]

    def names(self, k: str) -> tuple[str, ...]:
        no, rest = self.need(k)
        toks = rest.split()
        if len(toks) == 1 and toks[0].isdigit():
            return tuple(str(i) for i in range(int(toks[0])))
        if not toks:
            raise self.error(f"line {no}: '{k}:' needs a count or a list of names")
        return tuple(toks)

    def _discount(self) -> float:
        no, disc = self.need("discount")
        try:
            return float(disc)
        except ValueError:
            raise self.error(f"line {no}: discount must be a number, got {disc!r}") from None

    def _sign(self) -> float:
        no, val = self.header.get("values", (0, "reward"))
        if val not in ("reward", "cost"):
            raise self.error(f"line {no}: values must be 'reward' or 'cost', got {val!r}")
        return -1.0 if val == "cost" else 1.0

    def index(self, kind: str, names_: tuple[str, ...], tok: str, no: int) -> list[int]:
        if tok == "*":
            return list(range(len(names_)))
        if tok in names_:
            return [names_.index(tok)]
        if tok.isdigit() and int(tok) < len(names_):
            return [int(tok)]
        raise self.error(f"line {no}: unknown {kind} {tok!r}; expected one of {list(names_)} or an index")

    def numbers(self, toks: list[str], count: int, no: int, what: str) -> np.ndarray:
        try:
            vals = [float(t) for t in toks]
        except ValueError:
            raise self.error(f"line {no}: {what} must be numbers, got {' '.join(toks)!r}") from None
        if len(vals) != count:
            raise self.error(f"line {no}: {what} needs {count} numbers, got {len(vals)}")
        return np.array(vals)

    def start(self) -> np.ndarray:
        """``start:`` (a distribution, ``uniform`` or one state), ``start include:`` / ``start exclude:``."""
        n_s, states = len(self.states), self.states
        start = np.full(n_s, 1.0 / n_s)
        if "start" in self.header:
            no, rest = self.header["start"]
            toks = rest.split()
            if toks == ["uniform"]:
                pass
            elif len(toks) == 1 and not _is_float(toks[0]):
                start = np.zeros(n_s)
                start[self.index("state", states, toks[0], no)[0]] = 1.0
            else:
                start = self.numbers(toks, n_s, no, "start")
        for k in ("start include", "start exclude"):
            if k in self.header:
                no, rest = self.header[k]
                sel = [i for t in rest.split() for i in self.index("state", states, t, no)]
                mask = np.zeros(n_s, dtype=bool)
                mask[sel] = True
                if k == "start exclude":
                    mask = ~mask
                start = np.where(mask, 1.0, 0.0) / mask.sum()
        return start

    @staticmethod
    def _fields(rest: str) -> tuple[list[str], list[str]]:
        """An entry's ``:``-separated names and its numbers."""
        fields = [f.strip() for f in rest.split(":")]
        last = fields[-1].split()
        return fields[:-1] + ([last[0]] if last else []), last[1:]

    def entry(self, arr: np.ndarray, k: str, no: int, rest: str) -> None:
        """A ``T:``, ``O:`` or ``R:`` entry: one number, a row or a matrix (the last axes of ``arr``
        its names leave open); a probability row or matrix may be ``uniform``, a ``T:`` matrix
        ``identity``; rewards are negated where the file gives costs."""
        specs, vals = self._fields(rest)
        if not (2 if k == "R" else 1) <= len(specs) <= arr.ndim:
            raise self.error(f"line {no}: malformed {k} entry")
        third = ("observation", self.observations) if k == "O" else ("state", self.states)
        kinds = (("action", self.actions), ("state", self.states), third, ("observation", self.observations))
        where = [self.index(*kind, spec, no) for kind, spec in zip(kinds, specs, strict=False)]
        shape = arr.shape[len(specs) :]
        value: np.ndarray
        if vals == ["uniform"] and shape and k != "R":
            value = np.full(shape, 1.0 / shape[-1])
        elif vals == ["identity"] and len(shape) == 2 and k == "T":
            value = np.eye(len(self.states))
        else:
            what = ("entry", "row", "matrix")[len(shape)]
            value = (self.sign if k == "R" else 1.0) * self.numbers(vals, int(np.prod(shape)), no, f"{k} {what}").reshape(shape)
        arr[np.ix_(*where)] = value


def _is_float(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


# --------------------------------------------------------------------------- POMDPX


def pomdpx_factors(pomdp: AssistancePOMDP) -> dict[str, np.ndarray]:
    """The conditional tables of the POMDPX export, axes in the order of their parents, last axis
    the variable itself:

    * ``experience``  P(E' | T, C, a) = sum_o P(o | T, C, a) P(E' | o, C, a), axes [a, t, c, e];
    * ``human``       P(o | E', T, C, a) = P(o | T, C, a) P(E' | o, C, a) / P(E' | T, C, a),
      axes [a, t, c, e, o] (where P(E' | T, C, a) = 0 the row is never reached and is P(o | T, C, a));
    * ``trust``       P(T' | T, E', C, a), axes [a, c, e, t, u];
    * ``complexity``  P(C'), repeated for each action, axes [a, c'].

    P(E' | T, C, a) P(o | E', T, C, a) = P(o, E' | T, C, a): the product of the tables is the
    model's kernel P(o, E', T' | T, C, a) P(C')."""
    joint = np.einsum("cato,caoe->atceo", pomdp.emission, pomdp.experience)  # P(o, E' | T, C, a)
    p_e = joint.sum(axis=-1)  # [a, t, c, e]
    prior = np.broadcast_to(np.transpose(pomdp.emission, (1, 2, 0, 3))[:, :, :, None, :], joint.shape)
    with np.errstate(invalid="ignore", divide="ignore"):
        human = np.where(p_e[..., None] > 0, joint / p_e[..., None], prior)
    return {
        "experience": p_e,
        "human": human,
        "trust": np.transpose(pomdp.trust_transition, (1, 0, 2, 3, 4)),
        "complexity": np.tile(pomdp.complexity_probs, (len(ACTIONS), 1)),
    }


def write_pomdpx(pomdp: AssistancePOMDP, path: str | Path | None = None) -> str:
    """Write the assistance POMDP as a factored, mixed-observability POMDPX file (POMDPX 1.0, the
    format of the APPL/SARSOP toolkit).

    State variables: ``trust`` (hidden), ``experience`` and ``complexity`` (fully observed)
    and ``human`` (the human action of the trial just played, as in the flat export; hidden
    as a state variable and revealed by the observation variable ``human_action``).

    The mixed-observability model allows a fully observed variable only parents from the previous
    time slice (and the action), and a hidden variable only fully observed parents in its own
    slice.  The joint P(o, E' | T, C, a) is therefore written as P(E' | T, C, a) P(o | E', T, C, a)
    -- the same distribution, see :func:`pomdpx_factors` -- and the trust transition as
    P(T' | T, E', C, a).  Every table is written in full (``-`` for every parent and for the
    variable; a ``null`` parent takes a single ``-``).
    """
    T_ = _tokens(pomdp.trust_levels)
    C_ = _tokens(pomdp.complexities)
    f = pomdpx_factors(pomdp)
    root = ET.Element("pomdpx", version="0.1", id="trustseek")
    ET.SubElement(root, "Description").text = "trustseek assistance POMDP (state augmented with the last human action)"
    ET.SubElement(root, "Discount").text = _num(pomdp.discount)
    var = ET.SubElement(root, "Variable")

    def statevar(name, values, full):
        sv = ET.SubElement(var, "StateVar", vnamePrev=f"{name}_0", vnameCurr=f"{name}_1", fullyObs="true" if full else "false")
        ET.SubElement(sv, "ValueEnum").text = " ".join(values)

    statevar("trust", T_, False)
    statevar("experience", list(EXPERIENCES), True)
    statevar("complexity", C_, True)
    statevar("human", list(HUMAN_ACTIONS), False)
    ov = ET.SubElement(var, "ObsVar", vname="human_action")
    ET.SubElement(ov, "ValueEnum").text = " ".join(HUMAN_ACTIONS)
    av = ET.SubElement(var, "ActionVar", vname="robot")
    ET.SubElement(av, "ValueEnum").text = " ".join(ACTIONS)
    ET.SubElement(var, "RewardVar", vname="reward")

    def cond(parent, var_, parents, values, tag="CondProb", value_tag="ProbTable"):
        c = ET.SubElement(parent, tag)
        ET.SubElement(c, "Var").text = var_
        ET.SubElement(c, "Parent").text = " ".join(parents)
        p = ET.SubElement(c, "Parameter", type="TBL")
        e = ET.SubElement(p, "Entry")
        # one '-' per parent (a null parent has none) and, for a CondProb, one for the variable
        n_dash = sum(1 for x in parents if x != "null") + (value_tag == "ProbTable")
        ET.SubElement(e, "Instance").text = " ".join(["-"] * max(n_dash, 1))
        ET.SubElement(e, value_tag).text = " ".join(_num(x) for x in np.asarray(values).ravel())

    init = ET.SubElement(root, "InitialStateBelief")
    cond(init, "trust_0", ["null"], pomdp.model.initial)
    cond(init, "experience_0", ["null"], [0.0, 1.0])
    cond(init, "complexity_0", ["null"], pomdp.complexity_probs)
    cond(init, "human_0", ["null"], [0.0, 1.0])
    st = ET.SubElement(root, "StateTransitionFunction")
    cond(st, "complexity_1", ["robot"], f["complexity"])
    cond(st, "experience_1", ["robot", "trust_0", "complexity_0"], f["experience"])
    cond(st, "human_1", ["robot", "trust_0", "complexity_0", "experience_1"], f["human"])
    cond(st, "trust_1", ["robot", "complexity_0", "experience_1", "trust_0"], f["trust"])
    of = ET.SubElement(root, "ObsFunction")
    cond(of, "human_action", ["human_1"], np.eye(2))
    rf = ET.SubElement(root, "RewardFunction")
    R = np.transpose(pomdp.expected_reward, (1, 0, 2))  # [a, c, t]
    cond(rf, "reward", ["robot", "complexity_0", "trust_0"], R, "Func", "ValueTable")
    ET.indent(root)
    return _written('<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n", path)


def _written(text: str, path: str | Path | None) -> str:
    """``text``, written to ``path`` first when one is given."""
    if path is not None:
        Path(path).write_text(text, encoding="utf-8")
    return text


def export_assistance(
    pomdp: AssistancePOMDP, path: str | Path, fmt: str | None = None, initial_complexity: int | None = None
) -> str:
    """Export to ``.pomdp`` or ``.pomdpx`` (chosen by ``fmt`` or the file suffix)."""
    fmt = fmt or Path(path).suffix.lstrip(".")
    if fmt == "pomdp":
        return write_pomdp(flat_from_assistance(pomdp, initial_complexity), path)
    if fmt == "pomdpx":
        return write_pomdpx(pomdp, path)
    raise PomdpFileError([f"unknown export format {fmt!r}; expected 'pomdp' or 'pomdpx'"], str(path))


def flat_values_check(pomdp: AssistancePOMDP, horizons: Sequence[int] = (1, 2, 3)) -> list[dict[str, Any]]:
    """Finite-horizon values of the exported flat POMDP next to the belief-MDP values (both by
    exact expansion of the belief tree; any number of trust levels)."""
    flat = flat_from_assistance(pomdp)
    belief_mdp = pomdp.branch_model()
    b0 = pomdp.model.initial
    return [
        {
            "horizon": h,
            "complexity": cn,
            "flat": flat.finite_horizon_value(flat_belief(pomdp, b0, c), h),
            "belief_mdp": belief_mdp.finite_horizon_value(b0, h, c),
        }
        for h in horizons
        for c, cn in enumerate(pomdp.complexities)
    ]
