"""Python client for the experiment server (``trustseek serve``).

For a real robot, open a deploy session and ask the server before every trial::

    from trustseek.client import Client

    client = Client("http://127.0.0.1:8000", token="experimenter-token")
    robot = client.open_deploy(model="paper", policy={"kind": "trust-aware"})
    for complexity in ["low", "high", "high"]:
        action = robot.decide(complexity)          # "autonomous" or "ask"
        ...                                        # run the trial on the robot
        robot.observe(human_action="rely", outcome="success")
        print(robot.belief)                        # P(trust = high) after the update

The experimenter side (studies, participant links, live dashboard, export) is on the same
class: :meth:`Client.create_study`, :meth:`Client.create_sessions`,
:meth:`Client.dashboard` and :meth:`Client.export`.  Errors from the server are raised as
:class:`ServerError` with the HTTP status and the server's message.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx

from .errors import TrustseekError


class ServerError(TrustseekError):
    """The server refused a request (``status`` is the HTTP status code)."""

    def __init__(self, status: int, detail: Any, url: str):
        self.status = status
        self.detail = detail
        if isinstance(detail, dict) and "problems" in detail:
            lines = [str(p) for p in detail["problems"]]
        elif isinstance(detail, list):
            lines = [f"{'.'.join(str(x) for x in d.get('loc', []))}: {d.get('msg')}" for d in detail if isinstance(d, dict)]
        else:
            lines = [str(detail)]
        super().__init__([f"HTTP {status}: {x}" for x in lines] or [f"HTTP {status}"], url)


def _read_json(path: str | Path) -> Any:
    from .model.jsonfile import load_json

    return load_json(path)[0]


def _written(data: bytes, path: str | Path | None) -> bytes:
    """``data``, written to ``path`` when given."""
    if path is not None:
        Path(path).write_bytes(data)
    return data


def _check(r: httpx.Response) -> Any:
    if r.status_code >= 400:
        try:
            detail = r.json().get("detail", r.text)
        except ValueError:
            detail = r.text
        raise ServerError(r.status_code, detail, str(r.request.url))
    return r.json() if r.headers.get("content-type", "").startswith("application/json") else r.content


class Client:
    """The experimenter's handle on a server (``token`` = the experimenter token)."""

    def __init__(
        self,
        base_url: str = "http://127.0.0.1:8000",
        token: str | None = None,
        timeout: float = 30.0,
        http: httpx.Client | None = None,
    ):
        self.base_url = base_url.rstrip("/")
        self.token = token
        self._owns_http = http is None
        self.http = http or httpx.Client(base_url=self.base_url, timeout=timeout)

    def close(self) -> None:
        if self._owns_http:
            self.http.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _auth(self) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.token}"} if self.token else {}

    def _get(self, path: str, **params) -> Any:
        return _check(self.http.get(path, params=params or None, headers=self._auth()))

    def _post(self, path: str, body: dict | None = None, **params) -> Any:
        return _check(self.http.post(path, json=body, params=params or None, headers=self._auth()))

    # -- experimenter ------------------------------------------------------
    def create_study(self, config: dict[str, Any] | str | Path, status: str = "open") -> dict[str, Any]:
        """Create a study from its configuration (see docs/experiments.md); returns its summary
        (with ``link``, the study link for an online panel).  ``status="draft"`` makes a draft:
        links made in a draft are pilots, and the study link takes no one until it is opened.

        ``config`` may be a path to the study JSON.  Local files are read here and sent as
        JSON: ``task`` and ``model`` may be paths to task / trust-model JSON files (anything
        that is not a preset name and ends in ``.json``), and a block's ``policy`` may be the
        path of a policy JSON written by ``trustseek solve --out``."""
        raw = _read_json(config) if isinstance(config, (str, Path)) else config
        config = dict(raw)
        for key in ("task", "model"):
            v = config.get(key)
            if isinstance(v, Path) or (isinstance(v, str) and v.endswith(".json")):
                config[key] = _read_json(v)
        if "blocks" in config:
            config["blocks"] = [dict(b) for b in config["blocks"]]
        for b in config.get("blocks", []):
            if isinstance(b.get("policy"), (str, Path)):
                b["policy"] = _read_json(b["policy"])
        return self._post("/api/studies", config, status=status)

    def studies(self) -> list[dict[str, Any]]:
        return self._get("/api/studies")

    def create_sessions(
        self, study_id: str, participants: list[str] | None = None, count: int = 1, pilot: bool = False
    ) -> list[dict[str, Any]]:
        """Participant sessions: each with its ``link`` (the unguessable URL to hand out) and ``token``;
        ``pilot`` sessions are left out of the analysis export unless asked for."""
        body: dict[str, Any] = {"participants": participants} if participants is not None else {"count": count}
        return self._post(f"/api/studies/{study_id}/sessions", {**body, "pilot": pilot})

    def set_status(self, study_id: str, status: str) -> dict[str, Any]:
        """Open, pause or close a study (``"open"``, ``"paused"``, ``"closed"``)."""
        return self._post(f"/api/studies/{study_id}/status", {"status": status})

    def preview(self, study_id: str) -> str:
        """The link of a preview: the participant's view, kept out of the data."""
        return self._post(f"/api/studies/{study_id}/preview")["link"]

    def revoke(self, study_id: str, session_id: str) -> dict[str, Any]:
        """Revoke a participant's link: it shows a page saying so, and its session takes nothing more."""
        return self._post(f"/api/studies/{study_id}/sessions/{session_id}/revoke")

    def bundle(self, study_id: str, path: str | Path | None = None, pilot: bool = False) -> bytes:
        """The study's data bundle as a zip file (every table in CSV and Parquet, the study's
        configuration, a data dictionary); written to ``path`` when given."""
        return _written(self._get(f"/api/studies/{study_id}/bundle", pilot=pilot), path)

    def dashboard(self, study_id: str) -> dict[str, Any]:
        return self._get(f"/api/studies/{study_id}/dashboard")

    def export(self, study_id: str, path: str | Path | None = None, table: str = "trials") -> bytes:
        """The study's trials (canonical trial log) or ``table="events"``; CSV or Parquet by the
        suffix of ``path`` (CSV without a path).  Returns the bytes, and writes them to ``path``."""
        fmt = "parquet" if path is not None and Path(path).suffix == ".parquet" else "csv"
        return _written(self._get(f"/api/studies/{study_id}/export", table=table, format=fmt), path)  # any table

    # -- deploy ------------------------------------------------------------
    def open_deploy(
        self,
        model: str | dict = "paper",
        policy: dict | None = None,
        task: str | dict = "paper",
        label: str = "robot",
        seed: int = 0,
    ) -> DeploySession:
        """Open a decision session for a robot.  ``policy`` is a spec such as
        ``{"kind": "trust-aware"}`` / ``{"kind": "trust-agnostic"}`` or a full policy JSON."""
        body = {"model": model, "task": task, "policy": policy or {"kind": "trust-aware"}, "label": label, "seed": seed}
        info = self._post("/api/deploy/sessions", body)
        return DeploySession(self.http, info)


class DeploySession:
    """One robot's run: :meth:`decide` before each trial, :meth:`observe` after it.

    Trials are numbered here (1, 2, ...); both calls are idempotent for a trial number, so
    a retry after a network error is safe (pass ``trial=`` explicitly when retrying)."""

    def __init__(self, http: httpx.Client, info: dict[str, Any]):
        self.http = http
        self.info = info
        self.session_id: str = info["session_id"]
        self.token: str = info["token"]
        self.belief: float | None = info.get("belief")
        self.trial = 0  # the last committed trial
        self.action: str | None = None

    @classmethod
    def resume(cls, base_url: str, session_id: str, token: str, timeout: float = 30.0) -> DeploySession:
        """Reconnect to an existing deploy session (e.g. after the robot restarted)."""
        self = cls(httpx.Client(base_url=base_url.rstrip("/"), timeout=timeout), {"session_id": session_id, "token": token})
        st = self.state()
        self.trial, self.belief = st["trials_done"], st["belief"]
        return self

    def _auth(self) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.token}"}

    def _post(self, what: str, trial: int | None, **fields: Any) -> dict[str, Any]:
        """``decide`` or ``observe`` of trial ``trial`` (by default the next one) with ``fields``."""
        body = {"trial": self.trial + 1 if trial is None else trial, **fields}
        return _check(self.http.post(f"/api/deploy/sessions/{self.session_id}/{what}", json=body, headers=self._auth()))

    def _decided(self, out: dict[str, Any]) -> tuple[str, str]:
        self.action = out["robot_action"]
        return out["complexity"], out["robot_action"]

    def decide(self, complexity: str, trial: int | None = None) -> str:
        """The robot action (``autonomous`` or ``ask``) for the next trial of this complexity."""
        return self._decided(self._post("decide", trial, complexity=complexity))[1]

    def choose(
        self, remaining: dict[str, int], visible: dict[str, int] | None = None, trial: int | None = None
    ) -> tuple[str, str]:
        """For a ``schedule`` policy: tell the service which items remain (and which are visible,
        when the policy sees a window); returns the (complexity, robot action) of the next trial."""
        seen = {} if visible is None else {"visible": visible}
        return self._decided(self._post("decide", trial, remaining=remaining, **seen))

    def observe(self, human_action: str | None = None, outcome: str | None = None, trial: int | None = None) -> float | None:
        """Report the trial: ``human_action`` ``intervene``/``rely`` (omit when the robot asked)
        and, when the human relied, ``outcome`` ``success``/``failure``.  Returns the new belief."""
        out = self._post("observe", trial, human_action=human_action, outcome=outcome)
        self.trial = max(self.trial, out["trial"]["trial"])
        self.belief = out["belief"]
        return self.belief

    def state(self) -> dict[str, Any]:
        return _check(self.http.get(f"/api/deploy/sessions/{self.session_id}", headers=self._auth()))
