"""Deploy sessions of every policy kind keep deciding after the server process is killed and
restarted: the stored policy loads back whatever the order of its keys (a real ``trustseek serve``
process, so that nothing is served from the previous process's caches)."""

from __future__ import annotations

import json

import pytest
from sqlalchemy import create_engine, text

from server_checks import POLICY_KINDS, check_policies_decide_after_restart
from trustseek.policies import policy_from_dict
from trustseek.policies.complexity import ComplexityPolicy

TOKEN = "restart-policies-token"


def test_every_policy_kind_decides_after_a_restart_on_sqlite(tmp_path):
    check_policies_decide_after_restart(f"sqlite:///{tmp_path / 'restart.sqlite'}", TOKEN)


def test_policies_stored_with_sorted_keys_still_load_after_a_restart(tmp_path):
    """Rows written by earlier versions hold the policy with its keys sorted (``p_ask`` as
    ``{"high": ..., "low": ...}`` while ``complexities`` is ``["low", "high"]``)."""
    db_url = f"sqlite:///{tmp_path / 'sorted.sqlite'}"

    def sort_stored_policies():
        eng = create_engine(db_url)
        with eng.begin() as c:
            rows = c.execute(text("select sha256, policy from policies")).all()
            assert len(rows) == len(POLICY_KINDS)
            for sha, blob in rows:
                c.execute(
                    text("update policies set policy = :p where sha256 = :s"),
                    {"p": json.dumps(json.loads(blob), sort_keys=True), "s": sha},
                )
            blob = c.execute(text("select policy from policies")).scalars().first()
        eng.dispose()
        assert '"p_ask": {"high"' in blob

    check_policies_decide_after_restart(db_url, TOKEN, sort_stored_policies)


def test_complexity_policies_load_p_ask_in_any_key_order():
    d = {
        "format": "trustseek.policy/1",
        "kind": "randomized",
        "complexities": ["low", "high"],
        "p_ask": {"high": 0.4, "low": 0.1},
    }
    pol = policy_from_dict(json.loads(json.dumps(d, sort_keys=True)))
    assert isinstance(pol, ComplexityPolicy)
    assert pol.p_ask.tolist() == [0.1, 0.4]  # aligned with complexities, not with the keys' order
    for p_ask in ({"low": 0.1}, {"low": 0.1, "high": 0.4, "medium": 0.2}, {"low": 0.1, "mid": 0.4}, [0.1, 0.4]):
        with pytest.raises(ValueError, match="p_ask must map each of"):
            policy_from_dict({**d, "p_ask": p_ask})
