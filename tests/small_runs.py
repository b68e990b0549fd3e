"""A small reproduction (every section and figure, on few simulated people), made once per test
process: the reproduction's tests and the report's share it."""

from __future__ import annotations

from functools import cache

from trustseek.reproduction.pipeline import ReproduceConfig, Reproduction, reproduce

SMALL = {
    "replicates": 2,
    "large_n": 400,
    "bootstrap": 0,
    "restarts": 2,
    "replicate_restarts": 1,
    "replicate_large_n": 200,
    "grid": 201,
    "jobs": 1,
    "sensitivity_samples": 8,
    "schedule_participants": 500,
    "types_participants": 300,
}


@cache
def small_reproduction() -> Reproduction:
    """The reproduction of seed 3 on :data:`SMALL`; its summary must not be changed by a test."""
    return reproduce(ReproduceConfig(seed=3, **SMALL))
