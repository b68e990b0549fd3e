"""Shared POMDP test material: small standard ``.pomdp`` texts (Tiger; a file with every entry
form) and pomdp-py's exact belief-tree value of a flat POMDP, an independent oracle."""

import numpy as np
import pomdp_py
from pomdp_py.algorithms import value_function

from trustseek.pomdp.flat import FlatPOMDP

TIGER = """discount: 0.95
values: reward
states: tiger-left tiger-right
actions: listen open-left open-right
observations: tiger-left tiger-right
start: uniform
T: listen
identity
T: open-left
uniform
T: open-right
uniform
O: listen
0.85 0.15
0.15 0.85
O: open-left
uniform
O: open-right
uniform
R: listen : * : * : * -1
R: open-left : tiger-left : * : * -100
R: open-left : tiger-right : * : * 10
R: open-right : tiger-left : * : * 10
R: open-right : tiger-right : * : * -100
"""

ENTRY_FORMS = """# every entry form
discount: 0.9
values: cost
states: 2
actions: go stay
observations: beep quiet
start include: 1
T: * : 0 : 1 1.0
T: * : 1 : 1 1.0
T: stay : 0
1 0
O: * : * : beep 0.25
O: * : * : quiet 0.75
O: go : 1
0.5 0.5
R: go : 0 : 1
4 6
R: stay : *
1 1
1 1
"""


# --------------------------------------------------------------------------- pomdp-py adapters


class _S(pomdp_py.State):
    def __init__(self, i):
        self.i = i

    def __hash__(self):
        return hash(self.i)

    def __eq__(self, other):
        return isinstance(other, _S) and other.i == self.i


class _A(pomdp_py.Action):
    def __init__(self, i):
        self.i = i

    def __hash__(self):
        return hash(("a", self.i))

    def __eq__(self, other):
        return isinstance(other, _A) and other.i == self.i


class _O(pomdp_py.Observation):
    def __init__(self, i):
        self.i = i

    def __hash__(self):
        return hash(("o", self.i))

    def __eq__(self, other):
        return isinstance(other, _O) and other.i == self.i


def pomdp_py_value(flat: FlatPOMDP, belief: np.ndarray, horizon: int) -> float:
    """pomdp-py's exact belief-tree value of a flat POMDP (its own belief update and recursion)."""

    class T(pomdp_py.TransitionModel):
        def probability(self, sp, s, a):
            return flat.transition[a.i, s.i, sp.i]

    class Obs(pomdp_py.ObservationModel):
        def probability(self, o, sp, a):
            return flat.observation[a.i, sp.i, o.i]

    class R(pomdp_py.RewardModel):
        def sample(self, s, a, sp):
            return float(flat.reward[a.i, s.i, sp.i] @ flat.observation[a.i, sp.i])

    S = [_S(i) for i in range(len(flat.states))]
    A = [_A(i) for i in range(len(flat.actions))]
    Z = [_O(i) for i in range(len(flat.observations))]
    b = {s: float(belief[s.i]) for s in S}
    return value_function.value(b, S, A, Z, T(), Obs(), R(), flat.discount, horizon=horizon)
