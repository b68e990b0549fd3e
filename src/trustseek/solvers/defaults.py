"""The solvers' option names and defaults, in a module that loads nothing (no numpy): the
command line's options name them in ``--help`` without loading a solver."""

from __future__ import annotations

#: the belief grid's default number of points and its methods (:mod:`.grid`, :mod:`.alpha`)
DEFAULT_GRID = 2001
METHODS = ("policy-iteration", "value-iteration")

#: the scheduling solver's item orders, value-function representations and default grid (:mod:`.scheduling`)
ORDERS = ("optimal", "easy-first", "hard-first", "alternating")
REPRESENTATIONS = ("alpha", "grid")
DEFAULT_SCHEDULE_GRID = 201

#: the solver ``solve_type_aware`` uses unless told otherwise (:mod:`.type_aware`)
DEFAULT_TYPE_AWARE_SOLVER = "point"
