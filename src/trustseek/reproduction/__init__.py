"""The paper's Sections V-VI end to end on simulated supervisors.

* :mod:`.config`     -- ``ReproduceConfig`` and the paper's reported numbers ``PAPER``;
* :mod:`.statistics` -- intervals of means, distributions over replicates, the Wilcoxon test;
* :mod:`.comparison` -- the paper's values next to the reproduction's, with verdicts;
* :mod:`.pipeline`   -- the run: experiments, fit, plan, replicates, costs, heterogeneity;
* :mod:`.coverage`   -- how often the fit's bootstrap intervals cover the truth.
"""

from .config import AGNOSTIC, AWARE, PAPER, ReproduceConfig
from .pipeline import Reproduction, reproduce, write_summary

__all__ = ["AGNOSTIC", "AWARE", "PAPER", "ReproduceConfig", "Reproduction", "reproduce", "write_summary"]
