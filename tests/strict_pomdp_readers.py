"""Strict readers of Cassandra's ``.pomdp`` format and of POMDPX, written from the published
documents rather than from the project's own reader, to check that exports load in the tools
they are for.

Cassandra (pomdp-solve's "POMDP file format" and "POMDP file grammar" pages):

* tokens: ``:``, ``*``, ``+``/``-`` signs, integers ``[0-9]+``, floats with at least one digit
  before and one after the point, identifiers ``[a-zA-Z][a-zA-Z0-9_-]*`` that are not keywords;
  ``#`` starts a comment; anything else is an error;
* ``pomdp_file ::= preamble start_state param_list``: the preamble (``discount``, ``values``,
  ``states``, ``actions``, ``observations``, each once, any order) comes first, then an optional
  ``start``, then ``T:``, ``O:`` and ``R:`` entries in any order (a later entry overrides);
* probabilities are unsigned; every transition and observation row and the start belief sum to 1.

POMDPX (the APPL/SARSOP "PomdpX File Format (version 1.0)" document and its XML schema):

* ``<pomdpx version=..>`` holds ``Description*``, ``Discount`` (a decimal in [0, 1)),
  ``Variable``, then ``InitialStateBelief``, ``StateTransitionFunction``, ``ObsFunction`` (when
  there is an observation variable) and ``RewardFunction``;
* variables: ``StateVar`` (``vnamePrev``, ``vnameCurr``, ``fullyObs``), ``ObsVar``,
  ``ActionVar`` (``ValueEnum`` or ``NumValues`` >= 2) and ``RewardVar``, all names distinct;
* a ``CondProb`` has ``Var``, ``Parent`` and ``Parameter type="TBL"`` with ``Entry`` elements;
  an ``Instance`` has one token per parent and one for the variable (a ``Func`` has none for the
  variable; a ``null`` parent, allowed only in the initial belief, has one token in all): a value
  name, ``*`` (the entry holds for every value) or ``-`` (the table enumerates the values, the
  last ``-`` varying fastest); the ``ProbTable`` has one number in [0, 1] per enumerated cell,
  or ``uniform`` / ``identity``; every cell must be given and every distribution sum to 1;
* the mixed-observability model: a transition's parents are the action, previous-slice state
  variables and same-slice state variables; a fully observed variable has no same-slice parent;
  a hidden variable has only fully observed same-slice parents; an observation depends on the
  action and next-slice state variables only; the reward on the action and state variables.

Both readers raise :class:`StrictFormatError` with the reason at the first violation.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

TOL = 1e-9


class StrictFormatError(ValueError):
    """The file breaks the published grammar or schema."""


# --------------------------------------------------------------------------- Cassandra .pomdp

KEYWORDS = {
    "discount",
    "values",
    "states",
    "actions",
    "observations",
    "T",
    "O",
    "R",
    "uniform",
    "identity",
    "reward",
    "cost",
    "start",
    "include",
    "exclude",
    "reset",
}
_HEADERS = {"discount", "values", "states", "actions", "observations", "start", "T", "O", "R"}
_TOKEN = re.compile(
    r"(?P<ws>[ \t\r\n]+)|(?P<comment>#[^\n]*)|(?P<float>[0-9]+\.[0-9]+)|(?P<int>[0-9]+)"
    r"|(?P<ident>[a-zA-Z][a-zA-Z0-9_\-]*)|(?P<punct>[:*+\-])"
)


@dataclass
class Tok:
    kind: str  # float, int, ident, keyword, punct
    text: str
    line: int


def tokenize(text: str) -> list[Tok]:
    out, pos, line = [], 0, 1
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            raise StrictFormatError(f"line {line}: unexpected character {text[pos]!r}")
        kind = m.lastgroup
        assert kind is not None
        word = m.group()
        # a number must not run straight into a letter or a point ('0.5.1', '1e-5', '2x')
        nxt = text[m.end() : m.end() + 1]
        if kind in ("float", "int") and (nxt.isalnum() or nxt in "._"):
            raise StrictFormatError(f"line {line}: malformed number starting {word + nxt!r}")
        if kind == "ident" and word in KEYWORDS:
            kind = "keyword"
        if kind not in ("ws", "comment"):
            out.append(Tok(kind, word, line))
        line += word.count("\n")
        pos = m.end()
    return out


@dataclass
class CassandraPOMDP:
    discount: float
    values: str
    states: list[str]
    actions: list[str]
    observations: list[str]
    start: np.ndarray
    T: np.ndarray  # [a, s, s']
    O: np.ndarray  # noqa: E741 -- [a, s', o]
    R: np.ndarray  # [a, s, s', o]


class _Parser:
    def __init__(self, toks: list[Tok]):
        self.toks, self.i = toks, 0

    def peek(self, k: int = 0) -> Tok | None:
        return self.toks[self.i + k] if self.i + k < len(self.toks) else None

    def line(self) -> str:
        t = self.peek() or (self.toks[-1] if self.toks else None)
        return f"line {t.line}" if t else "end of file"

    def take(self) -> Tok:
        t = self.peek()
        if t is None:
            raise StrictFormatError("unexpected end of file")
        self.i += 1
        return t

    def expect(self, text: str) -> None:
        t = self.take()
        if t.text != text:
            raise StrictFormatError(f"line {t.line}: expected {text!r}, got {t.text!r}")

    def at_number(self) -> bool:
        t = self.peek()
        if t is None:
            return False
        if t.kind in ("float", "int"):
            return True
        nxt = self.peek(1)
        return t.text in "+-" and t.kind == "punct" and nxt is not None and nxt.kind in ("float", "int")

    def number(self, prob: bool) -> float:
        t = self.take()
        sign = 1.0
        if t.kind == "punct" and t.text in "+-":
            if prob:
                raise StrictFormatError(f"line {t.line}: a probability has no sign")
            sign = -1.0 if t.text == "-" else 1.0
            t = self.take()
        if t.kind not in ("float", "int"):
            raise StrictFormatError(f"line {t.line}: expected a number, got {t.text!r}")
        v = sign * float(t.text)
        if prob and not 0.0 <= v <= 1.0:
            raise StrictFormatError(f"line {t.line}: probability {t.text} outside [0, 1]")
        return v

    def numbers(self, prob: bool) -> list[float]:
        vals = []
        while self.at_number():
            vals.append(self.number(prob))
        return vals


def read_cassandra(text: str) -> CassandraPOMDP:
    """Parse ``text`` strictly; returns the dense arrays."""
    p = _Parser(tokenize(text))
    pre: dict[str, object] = {}
    while (t := p.peek()) is not None and t.text in ("discount", "values", "states", "actions", "observations"):
        p.take()
        if t.text in pre:
            raise StrictFormatError(f"line {t.line}: '{t.text}:' given twice")
        p.expect(":")
        if t.text == "discount":
            pre[t.text] = p.number(prob=False)
        elif t.text == "values":
            v = p.take()
            if v.text not in ("reward", "cost"):
                raise StrictFormatError(f"line {v.line}: values must be reward or cost, got {v.text!r}")
            pre[t.text] = v.text
        else:
            nt = p.peek()
            if nt is not None and nt.kind == "int":
                pre[t.text] = [str(i) for i in range(int(p.take().text))]
            else:
                names = []
                while (nt := p.peek()) is not None and nt.kind == "ident":
                    names.append(p.take().text)
                nt = p.peek()
                if nt is not None and nt.kind == "keyword" and nt.text not in _HEADERS:
                    raise StrictFormatError(f"line {nt.line}: {nt.text!r} is a keyword and cannot be a name")
                if not names:
                    bad = p.peek()
                    raise StrictFormatError(
                        f"{p.line()}: '{t.text}:' needs a count or identifiers, got {bad.text if bad else 'nothing'!r}"
                    )
                if len(set(names)) != len(names):
                    raise StrictFormatError(f"line {t.line}: repeated name in '{t.text}:'")
                pre[t.text] = names
    for k in ("discount", "values", "states", "actions", "observations"):
        if k not in pre:
            raise StrictFormatError(f"{p.line()}: the preamble lacks '{k}:' (it must come before start and T/O/R)")
    discount = float(pre["discount"])  # type: ignore[arg-type]
    if not 0.0 <= discount <= 1.0:
        raise StrictFormatError(f"discount {discount} outside [0, 1]")
    S, A, Z = (list(pre[k]) for k in ("states", "actions", "observations"))  # type: ignore[call-overload]
    nS, nA, nZ = len(S), len(A), len(Z)

    def ref(names: list[str], what: str) -> list[int]:
        t = p.take()
        if t.text == "*":
            return list(range(len(names)))
        if t.kind == "int":
            if int(t.text) >= len(names):
                raise StrictFormatError(f"line {t.line}: {what} index {t.text} out of range")
            return [int(t.text)]
        if t.kind == "ident" and t.text in names:
            return [names.index(t.text)]
        raise StrictFormatError(f"line {t.line}: unknown {what} {t.text!r}")

    start = np.full(nS, 1.0 / nS)
    if (t := p.peek()) is not None and t.text == "start":
        p.take()
        nt = p.peek()
        if nt is not None and nt.text in ("include", "exclude"):
            mode = p.take().text
            p.expect(":")
            sel: list[int] = []
            while (
                (nt := p.peek()) is not None
                and (nt.kind in ("ident", "int") or nt.text == "*")
                and nt.text not in ("T", "O", "R")
            ):
                sel += ref(S, "state")
            mask = np.zeros(nS, bool)
            mask[sel] = True
            if mode == "exclude":
                mask = ~mask
            start = mask / mask.sum()
        else:
            p.expect(":")
            nt = p.peek()
            if nt is not None and nt.text == "uniform":
                p.take()
            elif nt is not None and nt.kind == "ident":
                start = np.eye(nS)[ref(S, "state")[0]]
            else:
                vals = p.numbers(prob=True)
                if len(vals) != nS:
                    raise StrictFormatError(f"line {t.line}: start needs {nS} probabilities, got {len(vals)}")
                start = np.array(vals)
        if abs(start.sum() - 1.0) > TOL:
            raise StrictFormatError(f"line {t.line}: start sums to {start.sum()!r}, not 1")

    T = np.zeros((nA, nS, nS))
    O = np.zeros((nA, nS, nZ))  # noqa: E741
    R = np.zeros((nA, nS, nS, nZ))
    while (t := p.peek()) is not None:
        p.take()
        if t.text not in ("T", "O", "R") or t.kind != "keyword":
            where = "in the preamble or start, which must come first" if t.text in pre or t.text == "start" else ""
            raise StrictFormatError(f"line {t.line}: expected T:, O: or R:, got {t.text!r} {where}".rstrip())
        p.expect(":")
        a = ref(A, "action")
        if t.text in ("T", "O"):
            arr, n_last, last_names, what = (T, nS, S, "state") if t.text == "T" else (O, nZ, Z, "observation")
            if p.peek() is not None and p.peek().text == ":":
                p.take()
                s = ref(S, "state")
                if p.peek() is not None and p.peek().text == ":":
                    p.take()
                    x = ref(last_names, what)
                    arr[np.ix_(a, s, x)] = p.number(prob=True)
                else:
                    nt = p.peek()
                    if nt is not None and nt.text == "uniform":
                        p.take()
                        row = np.full(n_last, 1.0 / n_last)
                    else:
                        row = np.array(p.numbers(prob=True))
                        if len(row) != n_last:
                            raise StrictFormatError(f"line {t.line}: {t.text} row needs {n_last} probabilities, got {len(row)}")
                    arr[np.ix_(a, s)] = row
            else:
                nt = p.peek()
                if nt is not None and nt.text == "uniform":
                    p.take()
                    mat = np.full((nS, n_last), 1.0 / n_last)
                elif nt is not None and nt.text == "identity" and t.text == "T":
                    p.take()
                    mat = np.eye(nS)
                else:
                    vals = p.numbers(prob=True)
                    if len(vals) != nS * n_last:
                        raise StrictFormatError(
                            f"line {t.line}: {t.text} matrix needs {nS * n_last} probabilities, got {len(vals)}"
                        )
                    mat = np.array(vals).reshape(nS, n_last)
                arr[a] = mat
        else:
            p.expect(":")
            s = ref(S, "state")
            if p.peek() is not None and p.peek().text == ":":
                p.take()
                s2 = ref(S, "state")
                if p.peek() is not None and p.peek().text == ":":
                    p.take()
                    z = ref(Z, "observation")
                    R[np.ix_(a, s, s2, z)] = p.number(prob=False)
                else:
                    vals = p.numbers(prob=False)
                    if len(vals) != nZ:
                        raise StrictFormatError(f"line {t.line}: R row needs {nZ} numbers, got {len(vals)}")
                    R[np.ix_(a, s, s2)] = vals
            else:
                vals = p.numbers(prob=False)
                if len(vals) != nS * nZ:
                    raise StrictFormatError(f"line {t.line}: R matrix needs {nS * nZ} numbers, got {len(vals)}")
                R[np.ix_(a, s)] = np.array(vals).reshape(nS, nZ)
    for name, arr, labels in (("T", T, (A, S)), ("O", O, (A, S))):
        sums = arr.sum(axis=-1)
        bad = np.argwhere(np.abs(sums - 1.0) > TOL)
        if len(bad):
            i, j = bad[0]
            raise StrictFormatError(f"{name}: {labels[0][i]} : {labels[1][j]} sums to {sums[i, j]!r}, not 1")
    if pre["values"] == "cost":
        R = -R
    return CassandraPOMDP(discount, str(pre["values"]), S, A, Z, start, T, O, R)


# --------------------------------------------------------------------------- POMDPX


@dataclass
class PomdpxVar:
    name: str
    values: list[str]
    kind: str  # state-prev, state-curr, obs, action
    observed: bool = False


@dataclass
class PomdpX:
    discount: float
    variables: dict[str, PomdpxVar]
    state_vars: list[tuple[str, str, bool]]  # (prev, curr, fully observed)
    # section -> var -> (parents, dense table: one axis per non-null parent, last axis the variable)
    tables: dict[str, dict[str, tuple[list[str], np.ndarray]]] = field(default_factory=dict)
    reward: dict[str, tuple[list[str], np.ndarray]] = field(default_factory=dict)


_BOOL = {"true": True, "1": True, "false": False, "0": False}
_SECTIONS = ("InitialStateBelief", "StateTransitionFunction", "ObsFunction", "RewardFunction")


def _text(elem: ET.Element, tag: str, where: str) -> str:
    found = [c for c in elem if c.tag == tag]
    if len(found) != 1 or found[0].text is None or not found[0].text.strip():
        raise StrictFormatError(f"{where}: needs exactly one non-empty <{tag}>")
    return found[0].text


def _xml_token(word: str, where: str) -> str:
    if not word or any(ch.isspace() for ch in word) or word in ("*", "-", "null"):
        raise StrictFormatError(f"{where}: {word!r} is not a usable name")
    return word


def _values(elem: ET.Element, where: str) -> list[str]:
    kids = [c.tag for c in elem]
    if kids == ["ValueEnum"]:
        vals = [_xml_token(w, where) for w in _text(elem, "ValueEnum", where).split()]
        if len(set(vals)) != len(vals) or not vals:
            raise StrictFormatError(f"{where}: ValueEnum needs distinct values")
        return vals
    if kids == ["NumValues"]:
        n = _text(elem, "NumValues", where).strip()
        if not n.isdigit() or int(n) < 2:
            raise StrictFormatError(f"{where}: NumValues must be an integer >= 2")
        return [f"s{i}" for i in range(int(n))]
    raise StrictFormatError(f"{where}: needs exactly one of <ValueEnum> or <NumValues>")


def read_pomdpx(text: str) -> PomdpX:
    """Parse a POMDPX document strictly; returns dense conditional tables and the reward."""
    try:
        root = ET.fromstring(text.encode("utf-8") if text.lstrip().startswith("<?xml") else text)
    except ET.ParseError as exc:
        raise StrictFormatError(f"not well-formed XML: {exc}") from None
    if root.tag != "pomdpx":
        raise StrictFormatError(f"root element is <{root.tag}>, not <pomdpx>")
    try:
        float(root.get("version", ""))
    except ValueError:
        raise StrictFormatError("<pomdpx> needs a numeric version attribute") from None
    tags = [c.tag for c in root]
    i = 0
    while i < len(tags) and tags[i] == "Description":
        i += 1
    if tags[i : i + 2] != ["Discount", "Variable"]:
        raise StrictFormatError("<pomdpx> must hold Description*, then <Discount>, then <Variable>")
    rest = tags[i + 2 :]
    for t in rest:
        if t not in _SECTIONS:
            raise StrictFormatError(f"unknown element <{t}> in <pomdpx>")
    for t in _SECTIONS:
        if rest.count(t) > 1:
            raise StrictFormatError(f"<{t}> appears {rest.count(t)} times")
    disc_text = _text(root, "Discount", "<Discount>").strip()
    if not re.fullmatch(r"[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)", disc_text):
        raise StrictFormatError(f"<Discount> {disc_text!r} is not a decimal number")
    discount = float(disc_text)
    if not 0.0 <= discount < 1.0:
        raise StrictFormatError(f"<Discount> {discount} outside [0, 1)")

    variables: dict[str, PomdpxVar] = {}
    state_vars: list[tuple[str, str, bool]] = []
    reward_vars: list[str] = []

    def declare(name: str, var: PomdpxVar) -> None:
        _xml_token(name, "variable name")
        if name in variables or name in reward_vars:
            raise StrictFormatError(f"variable name {name!r} declared twice")
        variables[name] = var

    var_elem = root.find("Variable")
    assert var_elem is not None
    for v in var_elem:
        where = f"<{v.tag}>"
        if v.tag == "StateVar":
            prev, curr = v.get("vnamePrev"), v.get("vnameCurr")
            if not prev or not curr:
                raise StrictFormatError(f"{where} needs vnamePrev and vnameCurr")
            fo = v.get("fullyObs", "false")
            if fo not in _BOOL:
                raise StrictFormatError(f"{where} {curr}: fullyObs must be true or false, got {fo!r}")
            vals = _values(v, f"{where} {curr}")
            declare(prev, PomdpxVar(prev, vals, "state-prev", _BOOL[fo]))
            declare(curr, PomdpxVar(curr, vals, "state-curr", _BOOL[fo]))
            state_vars.append((prev, curr, _BOOL[fo]))
        elif v.tag in ("ObsVar", "ActionVar"):
            name = v.get("vname")
            if not name:
                raise StrictFormatError(f"{where} needs vname")
            declare(name, PomdpxVar(name, _values(v, f"{where} {name}"), "obs" if v.tag == "ObsVar" else "action"))
        elif v.tag == "RewardVar":
            name = v.get("vname")
            if not name or len(v):
                raise StrictFormatError(f"{where} needs vname and no content")
            if name in variables or name in reward_vars:
                raise StrictFormatError(f"variable name {name!r} declared twice")
            reward_vars.append(name)
        else:
            raise StrictFormatError(f"unknown element {where} in <Variable>")
    obs_vars = [n for n, v in variables.items() if v.kind == "obs"]
    if not state_vars or not reward_vars or not any(v.kind == "action" for v in variables.values()):
        raise StrictFormatError("<Variable> needs at least one StateVar, one ActionVar and one RewardVar")
    required = ["InitialStateBelief", "StateTransitionFunction", "RewardFunction"] + (["ObsFunction"] if obs_vars else [])
    for t in required:
        if t not in rest:
            raise StrictFormatError(f"missing <{t}>")

    model = PomdpX(discount, variables, state_vars)
    for section in ("InitialStateBelief", "StateTransitionFunction", "ObsFunction"):
        elem = root.find(section)
        if elem is None:
            continue
        out: dict[str, tuple[list[str], np.ndarray]] = {}
        for cp in elem:
            if cp.tag != "CondProb":
                raise StrictFormatError(f"<{section}> holds <{cp.tag}>, expected <CondProb>")
            name, parents, table = _cond(cp, section, variables, prob=True)
            if name in out:
                raise StrictFormatError(f"<{section}>: two CondProb for {name}")
            out[name] = (parents, table)
        want = {
            "InitialStateBelief": {p for p, _, _ in state_vars},
            "StateTransitionFunction": {c for _, c, _ in state_vars},
            "ObsFunction": set(obs_vars),
        }[section]
        if set(out) != want:
            raise StrictFormatError(f"<{section}> must hold one CondProb for each of {sorted(want)}, has {sorted(out)}")
        model.tables[section] = out
    rf = root.find("RewardFunction")
    assert rf is not None
    for f in rf:
        if f.tag != "Func":
            raise StrictFormatError(f"<RewardFunction> holds <{f.tag}>, expected <Func>")
        name = _text(f, "Var", "<Func>").strip()
        if name not in reward_vars:
            raise StrictFormatError(f"<Func> Var {name!r} is not a RewardVar")
        model.reward[name] = _cond(f, "RewardFunction", variables, prob=False)[1:]
    if set(model.reward) != set(reward_vars):
        raise StrictFormatError(f"<RewardFunction> must hold one Func for each of {reward_vars}")
    return model


def _cond(cp: ET.Element, section: str, variables: dict[str, PomdpxVar], prob: bool) -> tuple[str, list[str], np.ndarray]:
    kids = [c.tag for c in cp]
    if kids != ["Var", "Parent", "Parameter"]:
        raise StrictFormatError(f"<{section}>: <{cp.tag}> must hold <Var>, <Parent>, <Parameter> in that order, has {kids}")
    var_words = _text(cp, "Var", f"<{section}>").split()
    if len(var_words) != 1:
        raise StrictFormatError(f"<{section}>: <Var> must name one variable, got {var_words}")
    name = var_words[0]
    where = f"<{section}> {name}"
    parents = _text(cp, "Parent", where).split()
    if prob:
        v = variables.get(name)
        kind = {"InitialStateBelief": "state-prev", "StateTransitionFunction": "state-curr", "ObsFunction": "obs"}[section]
        if v is None or v.kind != kind:
            raise StrictFormatError(f"{where}: <Var> must be a declared {kind} variable")
    null = parents == ["null"]
    if "null" in parents and not null:
        raise StrictFormatError(f"{where}: 'null' must be the only parent")
    if null and section != "InitialStateBelief":
        raise StrictFormatError(f"{where}: a 'null' parent is allowed only in the initial belief")
    for par in [] if null else parents:
        pv = variables.get(par)
        if pv is None:
            raise StrictFormatError(f"{where}: parent {par!r} is not declared")
        if parents.count(par) > 1:
            raise StrictFormatError(f"{where}: parent {par!r} repeated")
        _check_parent(section, name, variables, pv, where)
    param = cp.find("Parameter")
    assert param is not None
    if param.get("type", "TBL") != "TBL":
        raise StrictFormatError(f"{where}: only Parameter type TBL is defined for tables, got {param.get('type')!r}")
    axes = [] if null else [variables[p].values for p in parents]
    if prob:
        axes = axes + [variables[name].values]
    n_inst = 1 if null else len(parents) + (1 if prob else 0)
    shape = tuple(len(a) for a in axes)
    table = np.full(shape, np.nan)
    entries = list(param)
    if not entries or any(e.tag != "Entry" for e in entries):
        raise StrictFormatError(f"{where}: <Parameter> must hold <Entry> elements")
    for e in entries:
        inst = _text(e, "Instance", where).split()
        if len(inst) != n_inst:
            raise StrictFormatError(
                f"{where}: <Instance> {' '.join(inst)!r} has {len(inst)} tokens; "
                f"{'a null parent takes one' if null else 'expected one per parent' + (' and one for the variable' if prob else '')}"
                f" ({n_inst})"
            )
        if null:
            if inst != ["-"]:
                raise StrictFormatError(f"{where}: with a null parent the Instance must be '-'")
            sel: list[list[int] | slice] = [slice(None)]
            dash_axes = [0]
        else:
            sel, dash_axes = [], []
            for k, (tok, vals) in enumerate(zip(inst, axes, strict=True)):
                if tok == "-":
                    dash_axes.append(k)
                    sel.append(slice(None))
                elif tok == "*":
                    sel.append(slice(None))
                elif tok in vals:
                    sel.append([vals.index(tok)])
                else:
                    raise StrictFormatError(f"{where}: <Instance> value {tok!r} is not a value of its variable")
        value_tag = "ProbTable" if prob else "ValueTable"
        words = _text(e, value_tag, where).split()
        n_cells = int(np.prod([shape[k] for k in dash_axes])) if dash_axes else 1
        block = _entry_block(words, shape, dash_axes, n_cells, prob, null, where)
        # assign: '-' axes take the block's axes in order, '*' and named axes broadcast
        idx = np.ix_(*[list(range(shape[k])) if isinstance(s, slice) else s for k, s in enumerate(sel)])
        full = block
        for k in range(len(shape)):
            if k not in dash_axes:
                full = np.expand_dims(full, k)
        table[idx] = np.broadcast_to(full, table[idx].shape)
    if np.isnan(table).any():
        missing = tuple(int(x) for x in np.argwhere(np.isnan(table))[0])
        raise StrictFormatError(f"{where}: the entries leave cell {missing} unset")
    if prob:
        sums = table.sum(axis=-1)
        if np.any(np.abs(sums - 1.0) > TOL):
            bad = tuple(int(x) for x in np.argwhere(np.abs(sums - 1.0) > TOL)[0])
            raise StrictFormatError(f"{where}: the distribution at parents {bad} sums to {sums[bad]!r}, not 1")
    return name, parents, table


def _entry_block(words, shape, dash_axes, n_cells, prob, null, where) -> np.ndarray:
    dshape = tuple(shape[k] for k in dash_axes)
    if prob and words == ["uniform"]:
        if not null:
            raise StrictFormatError(f"{where}: 'uniform' is defined for the initial belief with a null parent only")
        return np.full(dshape, 1.0 / dshape[-1])
    if prob and words == ["identity"]:
        if len(dash_axes) < 2 or dash_axes[-2:] != [len(shape) - 2, len(shape) - 1] or shape[-1] != shape[-2]:
            raise StrictFormatError(f"{where}: 'identity' needs '-' for the last parent and the variable, of equal size")
        eye = np.eye(shape[-1])
        return np.broadcast_to(eye, dshape).copy()
    if any(w in ("uniform", "identity") for w in words):
        raise StrictFormatError(f"{where}: 'uniform' and 'identity' stand alone in a ProbTable")
    try:
        vals = np.array([float(w) for w in words])
    except ValueError:
        raise StrictFormatError(f"{where}: table entries must be numbers") from None
    if not np.all(np.isfinite(vals)):
        raise StrictFormatError(f"{where}: table entries must be finite")
    if prob and (np.any(vals < 0) or np.any(vals > 1)):
        raise StrictFormatError(f"{where}: a probability outside [0, 1]")
    if len(vals) != n_cells:
        raise StrictFormatError(f"{where}: the table has {len(vals)} numbers, the Instance enumerates {n_cells} cells")
    return vals.reshape(dshape)


def _check_parent(section: str, name: str, variables: dict[str, PomdpxVar], pv: PomdpxVar, where: str) -> None:
    if section == "InitialStateBelief":
        if pv.kind != "state-prev":
            raise StrictFormatError(f"{where}: initial-belief parents are state variables of the first slice")
    elif section == "StateTransitionFunction":
        if pv.kind == "obs":
            raise StrictFormatError(f"{where}: an observation variable cannot be a transition parent")
        if pv.kind == "state-curr":
            child = variables[name]
            if child.observed:
                raise StrictFormatError(
                    f"{where}: {name} is fully observed, so it cannot have a parent in its own time slice ({pv.name})"
                )
            if not pv.observed:
                raise StrictFormatError(
                    f"{where}: {name} is hidden, so its parents in its own time slice must be fully observed ({pv.name} is not)"
                )
            if pv.name == name:
                raise StrictFormatError(f"{where}: a variable cannot be its own parent")
    elif section == "ObsFunction":
        if pv.kind not in ("action", "state-curr"):
            raise StrictFormatError(f"{where}: observation parents are the action and next-slice state variables, not {pv.name}")
    elif pv.kind == "obs":
        raise StrictFormatError(f"{where}: reward parents are the action and state variables, not {pv.name}")


# --------------------------------------------------------------------------- joint of a POMDPX model


def pomdpx_transition(model: PomdpX) -> tuple[list[str], np.ndarray]:
    """The joint transition P(x' | x, a) of a POMDPX model over all state variables and actions,
    built from the CondProb tables in an order that respects same-slice parents.  Returns the
    axis names ([action, prev..., curr...]) and the array."""
    (action,) = [n for n, v in model.variables.items() if v.kind == "action"]
    prevs = [p for p, _, _ in model.state_vars]
    currs = [c for _, c, _ in model.state_vars]
    axes = [action, *prevs, *currs]
    letters = {n: chr(ord("a") + i) for i, n in enumerate(axes)}
    ops, subs = [], []
    for c in currs:
        parents, table = model.tables["StateTransitionFunction"][c]
        ops.append(table)
        subs.append("".join(letters[p] for p in parents) + letters[c])
    for n in axes:  # previous-slice variables no table depends on: the joint is constant along them
        if not any(letters[n] in sub for sub in subs):
            ops.append(np.ones(len(model.variables[n].values)))
            subs.append(letters[n])
    expr = ",".join(subs) + "->" + "".join(letters[n] for n in axes)
    return axes, np.einsum(expr, *ops)
