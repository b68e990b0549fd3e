"""The paper's Sections V-VI end to end on simulated supervisors: settings (:mod:`.config`),
the paper-vs-reproduction rows (:mod:`.comparison`), the run (:mod:`.pipeline`), its sections and the
bootstrap coverage study.  Names load on first use (``__init__.pyi``)."""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
