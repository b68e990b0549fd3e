"""The two-level compiled pass on step codes (one 2 x 2 matrix per transition row and emission
row, the counts per code folded into the tables) against the numpy reference: sequences of
mixed lengths (pairs and single sequences), unobserved outputs, and rescaled recursions."""

import numpy as np
import pytest

from trustseek.estimation import Params, encode, forward_backward, paper_spec
from trustseek.estimation.estep import Workspace
from trustseek.estimation.structure import Structure
from trustseek.model.presets import paper_model
from trustseek.simulation.designs import simulate_design


def mixed(n: int, seed: int):
    """n participants cut to random lengths (1 to 71 trials; some equal neighbours), some outputs missing."""
    rng = np.random.default_rng(seed)
    df = simulate_design(paper_model(), n, seed=seed)
    keep = {p: int(rng.choice([71, 71, 40, int(rng.integers(1, 72))])) for p in df["participant"].unique()}
    df = df[df["trial"] <= df["participant"].map(keep)].copy()
    df.loc[rng.random(len(df)) < 0.05, "human_action"] = None
    spec = paper_spec()
    seqs = encode(df, spec)
    return seqs, Structure(spec, seqs)


def both(seqs, s, p):
    ref = Workspace(seqs, 2, 2, s.Ue, s.Ut, method="loop").estep(p)
    got = Workspace(seqs, 2, 2, s.Ue, s.Ut, method="compiled").estep(p)
    return ref, got


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mixed_lengths_and_missing_outputs_match_numpy_to_rounding(seed):
    seqs, s = mixed(300, seed)  # more than one item of sequences
    assert len(set(seqs.lengths.tolist())) > 10 and (seqs.y < 0).sum() > (seqs.lengths.max() - seqs.lengths).sum()
    p = s.random(np.random.default_rng(seed))
    ref, got = both(seqs, s, p)
    assert got.loglik == pytest.approx(ref.loglik, rel=1e-13)
    for name in ("initial", "emission", "transition"):
        np.testing.assert_allclose(getattr(got, name), getattr(ref, name), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", [3, 4])
def test_rescaled_recursions_in_pairs_and_single_sequences(seed):
    """Cells down to 1e-60: trials of probability 1e-120 make both recursions rescale, in the
    pairs and in the single sequences."""
    seqs, s = mixed(40, seed)
    rng = np.random.default_rng(seed)
    p = s.random(rng)

    def squash(a):
        a = a * 10.0 ** -rng.choice([0, 30, 60], size=a.shape)
        return a / a.sum(-1, keepdims=True)

    p = Params(p.initial, squash(p.emission), squash(p.transition))
    ref, got = both(seqs, s, p)
    assert np.isfinite(ref.loglik) and ref.loglik < -5000  # far below 2**-200 per sequence
    assert got.loglik == pytest.approx(ref.loglik, rel=1e-11)
    for name in ("initial", "emission", "transition"):
        np.testing.assert_allclose(getattr(got, name), getattr(ref, name), rtol=1e-9, atol=1e-9)


def test_step_codes():
    eidx = np.array([[3, 1, 4], [0, 2, 2]], dtype=np.int32)
    tidx = np.array([[1, 0, 0], [2, 3, 0]], dtype=np.int32)
    assert forward_backward.step_codes(eidx, tidx, 5).tolist() == [[3, 1 * 5 + 1, 0 * 5 + 4], [0, 2 * 5 + 2, 3 * 5 + 2]]
