"""Policies: what the robot does on the next trial.

* :mod:`.base`         -- the ``Policy`` interface every policy implements, ``PolicyError``, and a
                          policy's ask regions as simulator bounds and as JSON;
* :mod:`.regions`      -- ask intervals and thresholds, extracted once for every policy;
* :mod:`.envelope`     -- upper envelopes of lines: two-level alpha vectors, and the operations
                          the exact alpha-vector backup is made of;
* :mod:`.grid_q`       -- ``TrustAwarePolicy``: greedy in Q tabulated on a belief grid;
* :mod:`.alpha_vector` -- ``AlphaVectorPolicy``, ``FlatAlphaPolicy`` (standard files) and
                          ``TypeAwarePolicy`` (alpha vectors over (type, trust) for an unknown
                          supervisor type);
* :mod:`.complexity`   -- ``ComplexityPolicy``: trust-agnostic, randomized, always/never ask;
* :mod:`.kinds`        -- the policy JSON: one loader per kind, ``policy_from_dict``, ``load_policy``;
* :mod:`.runner`       -- ``PolicyRunner``: a policy with its live belief, trial by trial;
* :mod:`.scheduling`   -- ``SchedulePolicy`` and ``ScheduleRunner``: which item next, and whether to ask.

Policies never solve anything: the solvers (``trustseek.solvers``) build them.

Each name is loaded on first use (the names are in ``__init__.pyi``).
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
