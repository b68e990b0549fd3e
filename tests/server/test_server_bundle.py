"""The data bundle of a finished study (``trustseek export STUDY --bundle DIR`` and the
dashboard's zip): every table in CSV and Parquet, the study's configuration and a data
dictionary; ``trustseek fit`` and ``trustseek validate --rating`` read it without any
preprocessing (through the command line)."""

from __future__ import annotations

import io
import json
import zipfile

import pandas as pd
import pytest
from fastapi.testclient import TestClient

from cli_runner import run_cli
from trustseek.server import create_app
from trustseek.server.export import DICTIONARY, TABLES

TOKEN = "experimenter-secret"
H = {"Authorization": f"Bearer {TOKEN}"}
STUDY = {
    "name": "bundle",
    "blocks": [
        {"name": "randomized", "policy": {"kind": "randomized"}, "schedule": {"counts": {"low": 3, "high": 5}}},
        {"name": "aware", "policy": {"kind": "trust-aware"}, "schedule": {"counts": {"low": 3, "high": 5}}},
    ],
    "counterbalance": "rotate",
    "self_report": "trial",
    "practice": {"trials": ["low"]},
    "quiz": {"questions": [{"id": "q", "text": "Space...", "options": ["intervenes", "pauses"], "answer": 0}]},
    "questionnaires": [
        {"name": "end", "items": [{"id": "a", "text": "Choose 1.", "check": 1}, {"id": "b", "text": "I trust it."}]}
    ],
    "panel": {"completion_code": "C"},
}


def run_participant(client, study_id: str, k: int, pilot: bool = False) -> None:
    (info,) = client.post(f"/api/studies/{study_id}/sessions", json={"count": 1, "pilot": pilot}, headers=H).json()
    sid, h = info["session_id"], {"Authorization": f"Bearer {info['token']}"}
    client.post(f"/api/sessions/{sid}/consent", json={"agree": True, "panel": {"PROLIFIC_PID": f"pid-{k}"}}, headers=h)
    st = client.post(f"/api/sessions/{sid}/quiz", json={"attempt": 1, "answers": {"q": 0}}, headers=h).json()["state"]
    while not st["ended"]:
        if st["report_due"] is not None:
            value = float(20 + 60 * ((st["report_due"] + k) % 3 == 0))
            st = client.post(
                f"/api/sessions/{sid}/reports", json={"after_trial": st["report_due"], "value": value}, headers=h
            ).json()
            st = st["state"]
        elif st["questionnaire"]:
            body = {"questionnaire": "end", "after_trial": st["questionnaire"]["after_trial"], "answers": {"a": 1, "b": 5}}
            st = client.post(f"/api/sessions/{sid}/questionnaires", json=body, headers=h).json()["state"]
        else:
            cur = st["current"]
            human = "intervene" if cur["robot_action"] == "ask" or (cur["trial"] + k) % 4 == 0 else "rely"
            body = {"trial": cur["trial"], "submission_id": f"s{cur['trial']}", "human_action": human, "events": [{"type": "x"}]}
            r = client.post(f"/api/sessions/{sid}/trials", json=body, headers=h)
            assert r.status_code == 200, r.text
            st = r.json()["state"]


@pytest.fixture
def finished(tmp_path):
    db = f"sqlite:///{tmp_path / 'bundle.sqlite'}"
    with TestClient(create_app(db, token=TOKEN)) as client:
        study = client.post("/api/studies", json=STUDY, headers=H).json()
        for k in range(4):
            run_participant(client, study["id"], k)
        run_participant(client, study["id"], 9, pilot=True)
        yield client, db, study["id"]


def test_the_bundle_holds_every_table_and_reads_back_through_fit_and_validate(finished, tmp_path):
    _, db, study = finished
    out = tmp_path / "bundle"
    code, text = run_cli(["export", study, "--db", db, "--bundle", str(out), "--json"])
    assert code == 0, text
    names = {p.name for p in out.iterdir()}
    assert names == {f"{t}.{x}" for t in TABLES for x in ("csv", "parquet")} | {"study.json", "dictionary.csv"}
    for t in TABLES:  # CSV and Parquet hold the same rows
        assert len(pd.read_csv(out / f"{t}.csv")) == len(pd.read_parquet(out / f"{t}.parquet")), t
    sessions = pd.read_parquet(out / "sessions.parquet")
    assert sorted(sessions["panel_id"]) == [f"pid-{k}" for k in range(4)]  # the pilot left out
    assert sessions[["started_at", "ended_at"]].notna().all().all() and (sessions["quiz_outcome"] == "passed").all()
    assert len(pd.read_csv(out / "quiz.csv")) == 4
    reports = pd.read_csv(out / "reports.csv")
    assert set(reports["questionnaire"]) == {"self_report", "end"} and reports["check_passed"].sum() == 4
    assert json.loads((out / "study.json").read_text())["config"]["quiz"]["questions"][0]["id"] == "q"
    dictionary = pd.read_csv(out / "dictionary.csv")
    assert dictionary["description"].notna().all() and set(dictionary["table"]) == set(TABLES)
    assert len(dictionary) == sum(len(DICTIONARY[t]) for t in TABLES)

    model = tmp_path / "model.json"
    code, text = run_cli(["fit", str(out / "trials.csv"), "--restarts", "2", "--out", str(model)])
    assert code == 0, text
    code, text = run_cli(["validate", str(out / "trials.csv"), "-m", str(model), "--rating", "self_report", "-b", "0", "--json"])
    assert code == 0, text
    assert json.loads(text[: text.rindex("}") + 1])["n_rated"] == 64  # 4 participants x 16 trials, every one rated
    code, text = run_cli(["fit", str(out / "trials.parquet"), "--restarts", "1", "--out", str(tmp_path / "m2.json")])
    assert code == 0, text


def test_the_dashboard_download_is_the_same_bundle_and_an_existing_folder_is_not_overwritten(finished, tmp_path):
    client, db, study = finished
    r = client.get(f"/api/studies/{study}/bundle", headers=H)
    assert r.status_code == 200 and r.headers["content-type"] == "application/zip"
    with zipfile.ZipFile(io.BytesIO(r.content)) as z:
        names = {n.split("/", 1)[1] for n in z.namelist()}
        trials = pd.read_csv(io.BytesIO(z.read(f"{study}-bundle/trials.csv")))
    assert "dictionary.csv" in names and trials["participant"].nunique() == 4
    with zipfile.ZipFile(io.BytesIO(client.get(f"/api/studies/{study}/bundle?pilot=true", headers=H).content)) as z:
        assert pd.read_csv(io.BytesIO(z.read(f"{study}-bundle/trials.csv")))["participant"].nunique() == 5
    full = tmp_path / "full"
    full.mkdir()
    (full / "keep.txt").write_text("mine")
    code, text = run_cli(["export", study, "--db", db, "--bundle", str(full)])
    assert code == 2 and "--bundle" in text and (full / "keep.txt").read_text() == "mine"
    code, text = run_cli(["export", study, "--db", db])
    assert code == 2 and "--bundle" in text


def test_the_study_command_shows_and_moves_the_lifecycle(finished):
    _, db, study = finished
    code, text = run_cli(["study", study, "--db", db, "--json"])
    assert code == 0, text
    shown = json.loads(text[: text.rindex("}") + 1])
    assert shown["status"] == "open" and shown["link_path"].startswith("/join/") and shown["sessions"]["done"] == 4
    assert shown["sessions"]["pilot"] == 1
    assert run_cli(["study", study, "--db", db, "--status", "paused"])[0] == 0
    code, text = run_cli(["study", study, "--db", db, "--status", "draft"])
    assert code == 2 and "a paused study cannot become draft" in text
    code, text = run_cli(["study", study, "--db", db, "--status", "shut"])
    assert code == 2 and "--status 'shut'" in text
    assert run_cli(["study", study, "--db", db, "--status", "closed"])[0] == 0
    assert "closed" in run_cli(["study", study, "--db", db])[1]


def test_export_writes_parquet_by_its_suffix_in_any_case(tmp_path):
    """``--out`` and ``--events`` ending in ``.PARQUET`` (the suffix check takes any case) are both
    Parquet files: the events table was written as CSV there."""
    db = f"sqlite:///{tmp_path / 'case.sqlite'}"
    with TestClient(create_app(db, token=TOKEN)) as client:
        blocks = [{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["low"]}}]
        study = client.post("/api/studies", json={"name": "case", "blocks": blocks}, headers=H).json()["id"]
        (info,) = client.post(f"/api/studies/{study}/sessions", json={"count": 1}, headers=H).json()
        h = {"Authorization": f"Bearer {info['token']}"}
        assert client.post(f"/api/sessions/{info['session_id']}/events", json={"events": [{"type": "x"}]}, headers=h).is_success
    out, events = tmp_path / "trials.PARQUET", tmp_path / "events.PARQUET"
    code, text = run_cli(["export", study, "--db", db, "--out", str(out), "--events", str(events)])
    assert code == 0, text
    assert len(pd.read_parquet(out)) == 0 and pd.read_parquet(events)["type"].tolist() == ["x"]
