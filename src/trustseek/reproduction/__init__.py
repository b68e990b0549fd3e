"""The paper's Sections V-VI end to end on simulated supervisors.

* :mod:`.config`     -- ``ReproduceConfig`` and the paper's reported numbers ``PAPER``;
* :mod:`.statistics` -- intervals of means, distributions over replicates, the Wilcoxon test;
* :mod:`.comparison` -- the paper's values next to the reproduction's, with verdicts;
* :mod:`.pipeline`   -- the run: experiments, fit, plan, replicates, costs, heterogeneity;
* :mod:`.coverage`   -- how often the fit's bootstrap intervals cover the truth.

Each name is loaded on first use (the names are in ``__init__.pyi``).
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
