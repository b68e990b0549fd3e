"""Study design and power analysis: the exact value of a policy under a true model (:mod:`.evaluation`), one
replicate of a study (:mod:`.replicate`) and the sweep over designs (:mod:`.sweep`).  Names load on first use
(``__init__.pyi``)."""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
