"""Solvers: turn a problem into a policy, ``solver.solve(problem) -> Policy``.

* :mod:`.base`           -- the ``Solver`` interface and its errors;
* :mod:`.defaults`       -- the solvers' option names and defaults (loads nothing: the command line's help reads them);
* :mod:`.registry`       -- every solver by name with its options (``make_solver``), and every policy
                            by a short spec (``policy_from_spec``), solved through it;
* :mod:`.grid`           -- the belief grid (two trust levels, both updates);
* :mod:`.alpha`          -- certified alpha vectors (two trust levels) and the exact backup they run;
* :mod:`.certified`      -- certified two-level solutions and the certified adaptive grid for the
                            eq.-3 update (its numerics);
* :mod:`.point`          -- point-based bounds (any number of trust levels, flat POMDPs too);
* :mod:`.agnostic`       -- the trust-agnostic optimum (Section VI-A);
* :mod:`.type_aware`     -- ``solve_type_aware``: the policy for a person of unknown supervisor type,
                            and the ``types`` solver (bounds that use the supervisor types);
* :mod:`.summary`        -- the machine-readable summary of a solved policy.

Inside: :mod:`.numerics` (policy evaluation, Howard's improvement, the point-based backup and
its controllers, controller values), :mod:`.upper_bounds` (the reachable and types solvers'
upper bounds).

Each name is loaded on first use (the names are in ``__init__.pyi``).
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
