from trustseek import paper_model, paper_task, solve, trust_agnostic


def test_paper_preset_threshold_structure():
    for update in ("bayes", "paper"):
        pol = solve(paper_model(), paper_task(), belief_update=update)
        th = pol.thresholds()
        assert th["low"] is None
        assert 0.72 <= th["high"] <= 0.80
    agn = trust_agnostic(paper_model(), paper_task())
    assert agn.p_ask.tolist() == [0.0, 1.0]
