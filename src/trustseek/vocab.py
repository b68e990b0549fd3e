"""The domain's words, once: every other module takes its names and indices from here.

* trust and complexity levels are user-chosen, ordered names; the paper uses ``low`` /
  ``high`` for both (trust ordered from lowest to highest, so for two levels the belief is
  P(trust = high) = ``b[-1]``);
* robot action ``a``: ``autonomous`` / ``ask``   (index 0 / 1);
* human action ``o``: ``intervene`` / ``rely``   (index 0 / 1);
* experience ``E``:   ``faulty`` / ``reliable``  (index 0 / 1);
* a *trial* is one attempt, a *participant* one supervisor, a *block* a run of trials under
  one policy.

It also holds the columns of a trial log, the belief-update and policy-kind names, and the
paper's design constants (Sections V and VI).
"""

from __future__ import annotations

from typing import Final

from .errors import TrustseekError

# --------------------------------------------------------------------------- levels and actions

LEVELS: Final = ("low", "high")  # the paper's trust and complexity levels
ACTIONS: Final = ("autonomous", "ask")
HUMAN_ACTIONS: Final = ("intervene", "rely")
EXPERIENCES: Final = ("faulty", "reliable")
AUTONOMOUS, ASK = 0, 1
INTERVENE, RELY = 0, 1
FAULTY, RELIABLE = 0, 1

# --------------------------------------------------------------------------- trial logs

#: the columns of the canonical trial log, in order (docs/data-format.md)
TRIAL_COLUMNS: Final = ("participant", "trial", "complexity", "robot_action", "human_action", "experience")
#: the categorical columns among them
CATEGORICAL_COLUMNS: Final = ("complexity", "robot_action", "human_action", "experience")

# --------------------------------------------------------------------------- belief updates

#: ``bayes``: the exact Bayes filter; ``paper``: eq. (3) as printed (ignores the human action)
BELIEF_UPDATES: Final = ("bayes", "paper")
UNOBSERVED: Final = -1  # index of a human action that was not recorded


class VocabularyError(TrustseekError, ValueError):
    """A name outside the vocabulary (e.g. an unknown belief update)."""


def check_belief_update(name: object, what: str = "belief update") -> str:
    """``name`` if it names a belief update, else a :class:`VocabularyError` naming the choices."""
    if name not in BELIEF_UPDATES:
        choices = " or ".join(repr(b) for b in BELIEF_UPDATES)
        raise VocabularyError([f"{what} must be {choices}, got {name!r}"])
    return str(name)


# --------------------------------------------------------------------------- policy kinds

#: the ``kind`` of a policy JSON: the robot's behaviour, by name
TRUST_AWARE, TRUST_AGNOSTIC = "trust-aware", "trust-agnostic"
RANDOMIZED, ALWAYS_ASK, NEVER_ASK = "randomized", "always-ask", "never-ask"
#: the kinds that look only at the complexity (ask with a fixed probability per complexity)
COMPLEXITY_POLICY_KINDS: Final = (TRUST_AGNOSTIC, RANDOMIZED, ALWAYS_ASK, NEVER_ASK)
#: the kinds a short policy spec (``{"kind": ...}``) can name
POLICY_SPEC_KINDS: Final = (TRUST_AWARE, *COMPLEXITY_POLICY_KINDS)

# --------------------------------------------------------------------------- the paper's design

#: Section V: trials per participant in each complexity (41 low, 30 high), 9 participants
PAPER_DATA_COUNTS: Final = (41, 30)
PAPER_DATA_PARTICIPANTS: Final = 9
#: Section V: the data-collection policy asks w.p. 0.10 in low and 0.40 in high complexity
PAPER_ASK_PROBABILITIES: Final = {"low": 0.10, "high": 0.40}
#: Section VI-B: each block has 17 low- and 17 high-complexity trials, 5 participants
PAPER_BLOCK_COUNTS: Final = (17, 17)
PAPER_EVALUATION_PARTICIPANTS: Final = 5
