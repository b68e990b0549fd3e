"""The paper's Sections V-VI end to end on simulated supervisors."""

from .pipeline import Reproduction, ReproduceConfig, reproduce

__all__ = ["ReproduceConfig", "Reproduction", "reproduce"]
