"""The 3-D supervision scene in headless Chromium (software WebGL), driven by its state
(``?manual=1``: the tests step the page's clock): autonomous failures show a cause that fits
the trial's complexity (a slip when low, a strike of the obstacle when high) and end with the
item on the floor in all three views; a success, an intervention
and a keyboard teleoperation whose contacts are logged; the 2-D scene where WebGL is disabled
or the study asks for it, recorded per session. Screenshots of every phase go to
``$TRUSTSEEK_ARTIFACTS`` (``scripts/screenshots.py`` puts them in docs/img/)."""

from __future__ import annotations

import io
import json
import os
from pathlib import Path

import pandas as pd
import pytest

from scene_drive import hold, start, step_until, teleoperate
from trustseek.client import Client
from trustseek.server.app import STATIC
from trustseek.testing.browser import CHROMIUM, launch_chromium, screenshot
from trustseek.testing.servers import ThreadServer

pytestmark = pytest.mark.browser

TOKEN = "scene-test-token"
BASE_W = 0.9  # the base's length along its heading (web/src/scene.ts)
# small pictures unless the screenshots are for the documentation
SHOTS = os.environ.get("TRUSTSEEK_SCENE_SHOTS") == "1"
VIEWPORT = {"width": 1280, "height": 720} if SHOTS else {"width": 1000, "height": 600}
QUERY = "?manual=1&quality=" + ("3" if SHOTS else "0")


def task(success: float) -> dict:
    c = {"probability": 0.5, "success": success}
    return {
        "complexities": {"low": {**c, "ask_experience": "faulty"}, "high": {**c, "ask_experience": "reliable"}},
        "rewards": {"autonomous_success": 2.0, "ask": 1.0, "intervene": 0.0, "autonomous_failure": -3.0},
        "discount": 0.987,
    }


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} is missing: run scripts/setup.sh")
    if not (STATIC / "participant.js").exists():
        pytest.fail("front end not built: run scripts/setup.sh (npm ci && npm run build in web/)")
    from playwright.sync_api import sync_playwright

    d = tmp_path_factory.mktemp("scene")
    out = Path(os.environ.get("TRUSTSEEK_ARTIFACTS", d))
    out.mkdir(parents=True, exist_ok=True)
    with ThreadServer(f"sqlite:///{d / 'scene.sqlite'}", TOKEN) as url, sync_playwright() as p:
        c = Client(url, TOKEN)
        browser = launch_chromium(p)
        yield c, browser, p, out
        browser.close()
        c.close()


def session(c: Client, study: dict) -> tuple[str, str]:
    s = c.create_study({"name": "scene", "animation_speed": 2.0, **study})
    return s["id"], c.create_sessions(s["id"], participants=["p"])[0]["link"]


def new_page(browser):
    page = browser.new_page(viewport=VIEWPORT)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    return page, errors


def shot(page, out: Path, name: str) -> None:
    if SHOTS:  # for the documentation: JPEG, smaller
        screenshot(page, path=str(out / f"scene-{name}.jpg"), quality=80)
    else:
        screenshot(page, path=str(out / f"scene-{name}.png"))


def _drawn(page) -> bool:
    """Whether each view (world, local, end-effector) shows a picture on the screen: the pixels of
    its canvas are not all of one colour."""
    from PIL import Image, ImageStat

    for view in ("#world", "#local", "#ee"):
        picture = Image.open(io.BytesIO(screenshot(page.locator(view)))).convert("L")
        if ImageStat.Stat(picture).stddev[0] < 5.0:
            return False
    return True


def events(c: Client, study_id: str) -> pd.DataFrame:
    ev = pd.read_csv(io.BytesIO(c.export(study_id, table="events")))
    ev["data"] = [json.loads(d) if isinstance(d, str) else {} for d in ev["data"]]
    return ev


def test_failures_show_their_complexitys_cause_and_the_item_is_on_the_floor_in_every_view(env):
    c, browser, _, out = env
    study_id, link = session(
        c, {"task": task(0.0), "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["low", "high"]}}]}
    )
    page, errors = new_page(browser)
    start(page, link, QUERY)
    assert page.evaluate("window.__scene.scene()") == "3d"
    causes = {}
    for trial in (1, 2):
        r = step_until(page, f"s.trial === {trial} && s.phase === 'approach'")
        complexity = r["s"]["complexity"]
        step_until(page, "s.phase !== 'approach'")
        if trial == 2:
            shot(page, out, "reach")
        step_until(page, "s.phase === 'outcome'")
        r = step_until(page, "g.cause !== null", frames=2)
        shot(page, out, f"failure-{complexity}-start")
        r = step_until(page, "s.phase === 'result'")
        g = r["g"]
        shot(page, out, f"failure-{complexity}")
        causes[complexity] = (g["cause"], g["struck"], page.text_content("#banner"))
        # the item lies on the floor, and every camera has it in its picture
        assert g["item"][2] < 0.1, g
        assert all(v["inFrame"] for v in g["views"].values()), g["views"]
        if g["cause"] == "strike":
            assert g["shoved"] > 0.05, g  # the obstacle was shoved aside
        assert g["calls"]["world"] <= 60 and g["calls"]["local"] <= 60 and g["calls"]["ee"] <= 60, g["calls"]
    # low complexity: the grasp slips; high: the base strikes the obstacle in its way
    assert causes["low"][0] == "slip" and "slipped" in causes["low"][2], causes
    assert causes["high"][0] == "strike" and causes["high"][1] in ("crate", "cart"), causes
    assert f"struck the {causes['high'][1]}" in causes["high"][2], causes
    page.close()
    assert errors == []
    ev = events(c, study_id)
    assert [d["scene"] for d in ev[ev["type"] == "scene"]["data"]] == ["3d"]
    assert [d["cause"] for d in ev[ev["type"] == "outcome_shown"]["data"]] == [causes["low"][0], causes["high"][0]]


def test_success_intervention_and_keyboard_teleoperation_with_contacts(env):
    c, browser, _, out = env
    study_id, link = session(
        c,
        {
            "task": task(1.0),
            "blocks": [
                {"policy": {"kind": "never-ask"}, "schedule": {"trials": ["low", "high"]}},
                {"policy": {"kind": "always-ask"}, "schedule": {"trials": ["high"]}},
            ],
        },
    )
    page, errors = new_page(browser)
    start(page, link, QUERY)
    # on its way: the page's clock stands until the test steps it, and nothing was drawn yet (the
    # documentation's picture of the approach was three empty views)
    at = step_until(page, "true", limit=1)["s"]["robot"]
    moving = step_until(page, f"Math.hypot(s.robot.x - {at['x']}, s.robot.y - {at['y']}) > 1.0 || s.phase !== 'approach'")
    assert moving["s"]["phase"] == "approach" and _drawn(page), moving["s"]
    shot(page, out, "approach")
    step_until(page, "s.phase === 'outcome'")
    r = step_until(page, "s.phase === 'result'")
    assert r["s"]["item"]["inBin"] and r["g"]["cause"] is None
    shot(page, out, "success")
    # trial 2: intervene during the approach, then teleoperate by keyboard
    step_until(page, "s.trial === 2 && s.phase === 'approach'")
    step_until(page, "true", limit=3)
    page.keyboard.press(" ")
    step_until(page, "s.phase === 'teleop'", limit=5)
    shot(page, out, "intervention")
    teleoperate(page, at_grasp=lambda pg: shot(pg, out, "teleop-grasp"))
    # trial 3: the robot asks; a reload part of the way resumes the teleoperation where it was
    step_until(page, "s.trial === 3 && s.phase === 'teleop'")
    shot(page, out, "ask")
    x0 = page.evaluate("window.trustseek.state().robot.x")
    hold(page, "ArrowUp", f"s.robot.x > {x0 + 0.5}")
    hold(page, "r", "s.robot.tool[2] > 0.8", dt=0.01)
    hold(page, "g", "s.robot.jaw < 0.5", dt=0.01)
    before = step_until(page, "true", frames=1, limit=1)["s"]["robot"]
    page.reload()
    page.wait_for_function("window.trustseek && window.trustseek.state().phase === 'teleop'")
    after = page.evaluate("window.trustseek.state().robot")
    for k in ("x", "y", "heading", "closed"):
        assert after[k] == pytest.approx(before[k], abs=1e-9), (k, before, after)
    assert after["tool"] == pytest.approx(before["tool"], abs=1e-9)
    page.keyboard.press("g")  # opened again
    # the base driven into the crate or the cart ahead: a contact, and the base pushed back from it
    s = step_until(page, "true", frames=1, limit=1)["s"]
    (o,) = [o for o in s["obstacles"] if o["kind"] != "spill"]
    s = hold(page, "ArrowUp", f"s.contacts > {s['contacts']}")["s"]
    assert s["robot"]["x"] + BASE_W / 2 <= o["x"] - 0.04, (s["robot"], o)
    hold(page, "ArrowDown", "s.robot.x < s.path[0].x + 0.4")  # back to the start, to drive around it
    hold(page, "f", "s.robot.tool[2] < 0.5", dt=0.01)  # the gripper down again: it clears the shelves as the base turns
    teleoperate(page)
    step_until(page, "s.phase === 'done'")
    page.close()
    assert errors == []
    ev = events(c, study_id)
    # every teleoperation struck the shelf with the arm once, the second the obstacle with the
    # base too; each contact says what was struck, and where the base was pushed back to
    contacts = ev[ev["type"] == "contact"]
    hits = [d["with"] for d in contacts["data"]]
    assert len(hits) >= 3 and set(hits) <= {"arm-shelf", "arm-product", "shelf", o["kind"]}, contacts
    assert all(len(d["gripper"]) == 3 for d in contacts["data"])
    base = contacts[[d["with"] == o["kind"] for d in contacts["data"]]]
    assert base["trial"].tolist() == [3] and base["data"].iloc[0]["x"] + BASE_W / 2 <= o["x"] - 0.04, base
    deposits = list(ev[ev["type"] == "deposit"]["data"])
    assert len(deposits) == 2 and all(d["contacts"] >= 1 and d["inputs"] > 10 and d["driven_m"] > 5 for d in deposits), deposits
    assert [d["phase"] for d in ev[ev["type"] == "resumed"]["data"]] == ["teleop"]
    assert [d["via"] for d in ev[ev["type"] == "intervene"]["data"]] == ["key"]


@pytest.mark.parametrize("how", ["webgl disabled", "study asks"])
def test_the_2d_scene_runs_where_webgl_is_missing_or_asked_for(env, how):
    c, browser, p, out = env
    extra = {"scene": "2d"} if how == "study asks" else {}
    # where the study asks, both trials fail: the 2-D scene shows the cause of its complexity
    trials, success = (["low"], 1.0) if how == "webgl disabled" else (["low", "high"], 0.0)
    study_id, link = session(
        c, {"task": task(success), "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"trials": trials}}], **extra}
    )
    b = launch_chromium(p, extra_args=("--disable-webgl", "--disable-3d-apis")) if how == "webgl disabled" else browser
    page, errors = new_page(b)
    start(page, link, "?manual=1")
    assert page.evaluate("window.__scene.scene()") == "2d"
    assert page.evaluate("document.body.dataset.scene") == "2d"
    banners = {}
    for n, complexity in enumerate(trials, 1):
        s = step_until(page, f"s.trial === {n} && s.phase === 'result'")["s"]
        banners[complexity] = page.text_content("#banner")
        if success == 0.0:
            # the item lies on the floor of the aisle, off the shelves (1.2 m deep on either side)
            assert s["item"]["fallen"] and not s["item"]["inBin"] and 1.2 < s["item"]["y"] < 4.8, s["item"]
            shot(page, out, f"fallback-2d-failure-{complexity}")
    if how == "webgl disabled":
        shot(page, out, "fallback-2d")
        b.close()
    else:
        page.close()
    assert errors == []
    ev = events(c, study_id)
    scenes = list(ev[ev["type"] == "scene"]["data"])
    assert [(d["scene"], d["reason"]) for d in scenes] == [("2d", "no webgl" if how == "webgl disabled" else "asked")]
    if success == 0.0:  # the same causes as in 3-D, named by the banner
        causes = [d["cause"] for d in ev[ev["type"] == "outcome_shown"]["data"]]
        assert causes == ["slip", "strike"], causes
        assert "slipped" in banners["low"], banners
        assert any(f"struck the {k} and the item fell" in banners["high"] for k in ("crate", "cart")), banners
