"""Estimation: the discrete IOHMM, its extended Baum-Welch algorithm, and the trust-model fit."""

from .fit import FitResult, decode, fit_trust_model, select_levels

__all__ = ["FitResult", "decode", "fit_trust_model", "select_levels"]
