"""The experiment server's export feeds the fit: a study run through the participant API is
exported with `trustseek export` and fitted with `trustseek fit` and `fit_trust_model`."""

from __future__ import annotations

import json

import numpy as np
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from trustseek import paper_model
from trustseek.cli import app
from trustseek.data.trials import read_trials
from trustseek.estimation.fit import fit_trust_model, from_model
from trustseek.estimation.iohmm import fit_iohmm, loglik
from trustseek.estimation.options import FitOptions
from trustseek.server import create_app

TOKEN = "fit-token"
H = {"Authorization": f"Bearer {TOKEN}"}


def test_exported_study_is_fitted(tmp_path):
    db = f"sqlite:///{tmp_path / 'fit.sqlite'}"
    rng = np.random.default_rng(3)
    model = paper_model()
    with TestClient(create_app(db, token=TOKEN)) as c:
        st = c.post(
            "/api/studies",
            json={"name": "fit", "blocks": [{"policy": {"kind": "randomized"}, "schedule": {"counts": {"low": 10, "high": 10}}}]},
            headers=H,
        ).json()
        sessions = c.post(f"/api/studies/{st['id']}/sessions", json={"count": 4}, headers=H).json()
        for s in sessions:
            ph = {"Authorization": f"Bearer {s['token']}"}
            base = f"/api/sessions/{s['session_id']}"
            c.post(f"{base}/consent", json={"agree": True}, headers=ph)
            trust = int(rng.random() < 0.5)  # some supervisors start with low trust
            for n in range(1, 21):
                cur = c.get(f"{base}/state", headers=ph).json()["current"]
                cx = 0 if cur["complexity"] == "low" else 1
                if cur["robot_action"] == "ask":
                    human = "intervene"
                else:  # a simulated supervisor: intervene with the paper model's probability
                    human = "intervene" if rng.random() < model.emission[cx, 0, trust, 0] else "rely"
                t = c.post(
                    f"{base}/trials",
                    json={"trial": n, "submission_id": f"{s['session_id']}-{n}", "human_action": human},
                    headers=ph,
                ).json()["trial"]
                a = 0 if t["robot_action"] == "autonomous" else 1
                # the experience (Section III): success, or a request to help in high complexity
                e = 1 if t["outcome"] == "success" or (a == 1 and cx == 1) else 0
                trust = int(rng.random() < model.transition[cx, a, e, trust, 1])
    out = tmp_path / "study.parquet"
    res = CliRunner().invoke(app, ["export", st["id"], "--db", db, "--out", str(out)])
    assert res.exit_code == 0, res.output
    frame = read_trials(out)
    assert len(frame) == 80 and frame.groupby("participant")["trial"].apply(list).map(lambda t: t == list(range(1, 21))).all()
    res = CliRunner().invoke(app, ["fit", str(out), "--restarts", "2", "--json"])
    assert res.exit_code == 0, res.output
    assert "80 trials" in json.loads(res.output)["model"]["notes"]
    fit = fit_trust_model(frame, options=FitOptions(restarts=2, seed=0))
    # (a log-likelihood of 0 up to rounding when every exported action had probability 1)
    assert np.isfinite(fit.loglik) and fit.loglik <= 1e-9
    # a fit that also starts from the model that generated the trials explains them at least as
    # well as that model (EM never lowers the likelihood; two random starts alone may stop at a
    # lesser local maximum on some schedules, and the sessions' schedules are random)
    spec, p_true = from_model(model)
    truth = loglik(fit.seqs, spec, p_true)
    assert np.isfinite(truth)
    from_truth = fit_iohmm(fit.seqs, spec, FitOptions(restarts=2, seed=0), init=[p_true])
    assert from_truth.loglik >= truth - 1e-6
    assert fit.counts["emission"].sum() > 0
