"""What the server remembers belongs to the application (``app.state``), never to a module: no
module of ``trustseek.server`` holds a mutable container at module level that its code
changes, nor a function cached at module level (``functools.cache``/``lru_cache``); and the
one bounded mapping (``server.cache.Bounded``) forgets the least recently used first."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import trustseek.server
from trustseek.server.cache import Bounded

SERVER = Path(trustseek.server.__file__).parent
_CONTAINERS = {"dict", "list", "set", "OrderedDict", "defaultdict", "deque", "Counter", "WeakValueDictionary"}
_MUTATORS = {"clear", "update", "pop", "popitem", "setdefault", "append", "add", "extend", "insert", "remove", "discard"}
_CACHES = {"cache", "lru_cache"}


def _container(value: ast.expr | None) -> bool:
    if isinstance(value, ast.Dict | ast.List | ast.Set | ast.DictComp | ast.ListComp | ast.SetComp):
        return True
    if isinstance(value, ast.Call):
        f = value.func
        return (f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else "") in _CONTAINERS
    return False


def module_caches(source: str) -> list[str]:
    """The module-level names of ``source`` bound to a mutable container that the module
    changes (item assignment or deletion, or a mutating method), and its module-level functions
    cached with ``functools``."""
    tree = ast.parse(source)
    names = set()
    found = []
    for node in tree.body:
        if isinstance(node, ast.Assign) and _container(node.value):
            names |= {t.id for t in node.targets if isinstance(t, ast.Name)}
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and _container(node.value):
            names.add(node.target.id)
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            for d in node.decorator_list:
                f = d.func if isinstance(d, ast.Call) else d
                if (f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else "") in _CACHES:
                    found.append(f"{node.name} (functools cache)")
    for node in ast.walk(tree):
        target = None
        if isinstance(node, ast.Subscript) and isinstance(node.ctx, ast.Store | ast.Del):
            target = node.value
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in _MUTATORS:
            target = node.func.value
        if isinstance(target, ast.Name) and target.id in names:
            found.append(target.id)
    return sorted(set(found))


def test_the_scan_finds_module_level_caches():
    """The scan itself: each kind of module-level cache is found, constants are not."""
    assert module_caches("_C: dict = {}\ndef f(k):\n    _C[k] = 1\n") == ["_C"]
    assert module_caches("_C = {}\ndef f():\n    _C.clear()\n") == ["_C"]
    assert module_caches("_L = list()\ndef f(x):\n    _L.append(x)\n") == ["_L"]
    assert module_caches("import functools\n@functools.lru_cache(8)\ndef f(x):\n    return x\n") == ["f (functools cache)"]
    assert module_caches("_WHY = {400: 'bad'}\ndef f(c):\n    return _WHY[c]\n") == []
    assert module_caches("class A:\n    def __init__(self):\n        self.c = {}\n        self.c[1] = 2\n") == []


@pytest.mark.parametrize("path", sorted(SERVER.rglob("*.py")), ids=lambda p: str(p.relative_to(SERVER)))
def test_no_module_level_cache_in_the_server(path):
    assert module_caches(path.read_text()) == [], f"{path.relative_to(SERVER)}: keep what it remembers on app.state"


def test_bounded_forgets_the_least_recently_used():
    b: Bounded[str, int] = Bounded(2)
    b.put("a", 1)
    b.put("b", 2)
    assert b.get("a") == 1  # "a" used: "b" is now the least recently used
    b.put("c", 3)
    assert "b" not in b and b.get("a") == 1 and b.get("c") == 3 and len(b) == 2
    b.pop("a")
    b.pop("missing")
    assert len(b) == 1 and b.get("a") is None


def test_the_application_remembers_what_its_sessions_need(tmp_path):
    """Two applications remember apart (as two worker processes): each its own studies'
    configurations, contexts and policies, and its own deploy plans."""
    from fastapi.testclient import TestClient

    from trustseek.server.app import create_app

    url = f"sqlite:///{tmp_path / 'caches.sqlite'}"
    apps = [create_app(url, token="t"), create_app(url, token="t")]
    h = {"Authorization": "Bearer t"}
    with TestClient(apps[0]) as c:
        blocks = [{"policy": {"kind": "trust-aware", "grid": 21}, "schedule": {"counts": {"low": 2}}}]
        study = c.post("/api/studies", json={"name": "c", "blocks": blocks}, headers=h).json()
        s = c.post(f"/api/studies/{study['id']}/sessions", json={"count": 1}, headers=h).json()[0]
        ph = {"Authorization": f"Bearer {s['token']}"}
        assert c.post(f"/api/sessions/{s['session_id']}/consent", json={"agree": True}, headers=ph).status_code == 200
        assert c.get(f"/api/sessions/{s['session_id']}/state", headers=ph).status_code == 200
        robot = c.post("/api/deploy/sessions", json={"policy": {"kind": "never-ask"}}, headers=h).json()
    first, second = apps[0].state, apps[1].state
    assert study["id"] in first.study_caches.configs and len(first.study_caches.contexts) == 1
    # the study's block policy is parsed once, in its context; one resolved policy each for the study and the robot
    block = first.study_caches.contexts.get(study["id"])[0]
    block._load = lambda: pytest.fail("the block's policy is parsed again")
    block.policy()
    assert len(first.study_caches.resolved) == 2
    assert first.deploy_plans.by_session.get(robot["session_id"]) is not None
    assert len(second.study_caches.configs) == len(second.deploy_plans.by_session) == 0
    for app in apps:
        app.state.deploy_store.close()


def test_a_state_request_asks_the_database_once_for_what_is_still_due(tmp_path):
    """The session's state says what is still due (a self-report, a questionnaire) and whether the
    session is over from one look at the reports and answers: the check of its end reuses it."""
    from fastapi.testclient import TestClient
    from sqlalchemy import event

    from trustseek.server.app import create_app

    app = create_app(f"sqlite:///{tmp_path / 'due.sqlite'}", token="t")
    h = {"Authorization": "Bearer t"}
    questionnaire = {"name": "q", "when": "end", "items": [{"id": "i1", "text": "It was easy."}]}
    with TestClient(app) as c:
        blocks = [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 1}}}]
        body = {"name": "due", "blocks": blocks, "self_report": "trial", "questionnaires": [questionnaire]}
        study = c.post("/api/studies", json=body, headers=h)
        assert study.status_code == 201, study.text
        s = c.post(f"/api/studies/{study.json()['id']}/sessions", json={"count": 1}, headers=h).json()[0]
        sid, ph = s["session_id"], {"Authorization": f"Bearer {s['token']}"}
        assert c.post(f"/api/sessions/{sid}/consent", json={"agree": True}, headers=ph).status_code == 200
        state = c.get(f"/api/sessions/{sid}/state", headers=ph).json()
        trial = {
            "trial": 1,
            "submission_id": "s1",
            "human_action": "rely" if state["current"]["robot_action"] == "autonomous" else "intervene",
        }
        assert c.post(f"/api/sessions/{sid}/trials", json=trial, headers=ph).status_code == 200
        seen: list[str] = []

        def count(conn, cursor, statement, *args):
            seen.append(statement)

        event.listen(app.state.engine, "before_cursor_execute", count)
        for expected in ({"report_due": 1}, {"report_due": None, "ended": False}):
            seen.clear()
            state = c.get(f"/api/sessions/{sid}/state", headers=ph).json()
            assert {k: state[k] for k in expected} == expected
            assert sum("FROM reports" in q for q in seen) == 1, seen
            assert sum("FROM answers" in q for q in seen) <= 1, seen
            if expected["report_due"]:
                assert c.post(f"/api/sessions/{sid}/reports", json={"after_trial": 1, "value": 5}, headers=ph).status_code == 200
        assert state["questionnaire"]["name"] == "q"
    app.state.deploy_store.close()
