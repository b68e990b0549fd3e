"""Seeds: an integer, or a numpy ``SeedSequence``, made the caller's own ``SeedSequence``."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np


def seed_sequence(seed: int | np.random.SeedSequence | None) -> np.random.SeedSequence:
    """``seed`` as a SeedSequence of the caller's own: an integer (None: fresh entropy) makes one, a
    SeedSequence is copied as it stands (its children spawned so far counted), so that what the
    caller spawns never moves the one given: the same seed gives the same numbers however often
    it is passed."""
    import numpy as np  # here: the command line's help loads no numpy

    if isinstance(seed, np.random.SeedSequence):
        return np.random.SeedSequence(
            seed.entropy, spawn_key=seed.spawn_key, pool_size=seed.pool_size, n_children_spawned=seed.n_children_spawned
        )
    return np.random.SeedSequence(seed)
