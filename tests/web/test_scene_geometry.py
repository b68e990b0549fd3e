"""The 3-D scene's geometry (web/src/scene3d/), run in node: for any scene seed and complexity,
the planned reach never brings a link of the arm into a shelf board or a product box, nor do
random teleoperated gripper moves (between two accepted configurations either), the base's
drive keeps its footprint out of the obstacles, accelerates from rest and turns without jumps.
The outcome's animations (3-D, and the 2-D scene's, web/src/outcome2d.ts) show the cause of the
trial's complexity and start alike whatever the outcome."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest
from hypothesis import Phase, given, settings
from hypothesis import strategies as hs

WEB = Path(__file__).resolve().parents[2] / "web"
ESBUILD = WEB / "node_modules" / ".bin" / "esbuild"

# reads {"seeds": [...], "products_out": bool (a product put in front of the item)} on stdin, prints one result per seed and complexity
PROBE = """
import { makeLayout, BASE_W, BASE_H } from "%(web)s/src/scene";
import { makeAisle } from "%(web)s/src/scene3d/geometry";
import { planReach, reachCollisions } from "%(web)s/src/scene3d/arm";
import { planPath, Drive } from "%(web)s/src/scene3d/drive";
import { readFileSync } from "node:fs";

const req = JSON.parse(readFileSync(0, "utf8"));
const out = [];
for (const seed of req.seeds) for (const high of [false, true]) {
  const layout = makeLayout(seed, high);
  const aisle = makeAisle(layout, seed);
  if (req.products_out) { // a product left standing in front of the item
    const it = aisle.item, s = Math.sign(aisle.front - it.y);
    aisle.products.push({ min: [it.x - 0.08, Math.min(aisle.front, aisle.front - s * 0.15), it.z - 0.08], max: [it.x + 0.08, Math.max(aisle.front, aisle.front - s * 0.15), it.z + 0.1], color: "#000" });
  }
  const drive = new Drive(planPath(layout));
  const end = drive.at(drive.duration + 1);
  const plan = planReach(end, aisle);
  // the base's footprint (its turning circle at corners, its rectangle on the straights)
  let overlap = 0, maxStep = 0, maxTurn = 0, prev = drive.at(0);
  const dt = 0.02;
  for (let t = dt; t <= drive.duration + dt; t += dt) {
    const p = drive.at(t);
    maxStep = Math.max(maxStep, Math.hypot(p.x - prev.x, p.y - prev.y) / dt);
    maxTurn = Math.max(maxTurn, Math.abs(p.heading - prev.heading) / dt);
    const c = Math.cos(p.heading), s = Math.sin(p.heading);
    const corners = [[1, 1], [1, -1], [-1, -1], [-1, 1]].map(([a, b]) => [p.x + c * a * BASE_W / 2 - s * b * BASE_H / 2, p.y + s * a * BASE_W / 2 + c * b * BASE_H / 2]);
    for (const o of layout.obstacles) {
      // separating axes: the obstacle's (x, y) and the base's (heading and its normal)
      const oc = [[o.x, o.y], [o.x + o.w, o.y], [o.x + o.w, o.y + o.h], [o.x, o.y + o.h]];
      const apart = [[1, 0], [0, 1], [c, s], [-s, c]].some(([ax, ay]) => {
        const pa = corners.map(([x, y]) => x * ax + y * ay), pb = oc.map(([x, y]) => x * ax + y * ay);
        return Math.max(...pa) <= Math.min(...pb) || Math.max(...pb) <= Math.min(...pa);
      });
      if (!apart) overlap++;
    }
    prev = p;
  }
  const v0 = Math.hypot(drive.at(0.1).x - drive.at(0).x, drive.at(0.1).y - drive.at(0).y) / 0.1;
  out.push({ seed, high, reachable: !!plan, hits: plan ? reachCollisions(plan, aisle).length : -1, overlap, maxStep, maxTurn, v0,
             end: [end.x - layout.pregrasp.x, end.y - layout.pregrasp.y, end.heading], level: aisle.item.level });
}
console.log(JSON.stringify(out));
"""


def bundle(d: Path, name: str, source: str) -> Path:
    """``source`` (TypeScript importing web/src) bundled by esbuild into ``d/name.mjs`` for node."""
    if shutil.which("node") is None or not ESBUILD.exists():
        pytest.fail("node and web/node_modules are needed: run scripts/setup.sh")
    (d / f"{name}.ts").write_text(source % {"web": WEB.as_posix()})
    cmd = [str(ESBUILD), str(d / f"{name}.ts"), "--bundle", "--platform=node", "--format=esm", f"--outfile={d / f'{name}.mjs'}"]
    subprocess.run([*cmd, "--log-level=warning"], check=True)
    return d / f"{name}.mjs"


def node_json(script: Path, req: dict) -> list[dict]:
    """What the bundled ``script`` prints (JSON) for ``req`` on its stdin."""
    res = subprocess.run(["node", str(script)], input=json.dumps(req), capture_output=True, text=True, check=True, timeout=120)
    return json.loads(res.stdout)


@pytest.fixture(scope="module")
def probe(tmp_path_factory) -> Path:
    return bundle(tmp_path_factory.mktemp("probe"), "probe", PROBE)


def run(probe: Path, seeds: list[int], products_out: bool = False) -> list[dict]:
    return node_json(probe, {"seeds": seeds, "products_out": products_out})


# one node run per example; no shrinking (each example is a batch of seeds, printed when one fails)
@settings(max_examples=2, deadline=None, derandomize=True, phases=[Phase.explicit, Phase.generate])
@given(hs.lists(hs.integers(0, 2**31 - 1), min_size=50, max_size=50, unique=True))
def test_the_planned_reach_never_enters_a_shelf_or_a_product(probe, seeds):
    rows = run(probe, seeds)
    assert [r for r in rows if not r["reachable"] or r["hits"] != 0] == []
    assert {r["level"] for r in rows} == {0, 1, 2, 3}  # every shelf height is reached


def test_the_check_finds_a_product_in_the_way(probe):
    rows = run(probe, list(range(20)), products_out=True)
    assert all(r["hits"] > 0 for r in rows)


# one node run per example; no shrinking (each example is a batch of seeds, printed when one fails)
@settings(max_examples=2, deadline=None, derandomize=True, phases=[Phase.explicit, Phase.generate])
@given(hs.lists(hs.integers(0, 2**31 - 1), min_size=30, max_size=30, unique=True))
def test_the_base_drives_around_the_obstacles_and_accelerates(probe, seeds):
    rows = run(probe, seeds)
    for r in rows:
        assert r["overlap"] == 0, r
        assert r["maxStep"] <= 1.6 + 1e-6, r  # never faster than V_MAX (m/s)
        assert r["maxTurn"] <= 2.0 + 1e-6, r  # nor turning faster than W_MAX (rad/s)
        assert r["v0"] < 0.1, r  # it sets off from rest
        assert max(abs(x) for x in r["end"]) < 1e-6, r  # and stops at the pregrasp point, facing along the aisle


# teleoperation: random gripper moves from the robot's place before the item, each through
# moveTool; the arm between two accepted configurations (5 interpolated poses) must stay clear
TELEOP = """
import { makeLayout, rng } from "%(web)s/src/scene";
import { makeAisle } from "%(web)s/src/scene3d/geometry";
import { armHits, mix } from "%(web)s/src/scene3d/arm";
import { planPath, Drive } from "%(web)s/src/scene3d/drive";
import { moveTool, nearBoxes, solve, toBase } from "%(web)s/src/scene3d/teleop";
import { readFileSync } from "node:fs";

const req = JSON.parse(readFileSync(0, "utf8"));
const out = [];
for (const seed of req.seeds) {
  const layout = makeLayout(seed, seed %% 2 === 1);
  const aisle = makeAisle(layout, seed);
  const drive = new Drive(planPath(layout));
  const pose = drive.at(drive.duration + 1);
  const boxes = nearBoxes(aisle, pose);
  const r = rng(seed + 7);
  const it = aisle.item;
  let tool = toBase(pose, [it.x, it.y + Math.sign(pose.y - it.y) * 0.62, it.z]);
  let j = solve(pose, tool, 1);
  let accepted = 0, refused = 0, crossings = 0, reached = 0;
  for (let i = 0; i < req.moves && j; i++) {
    // a move of up to 6 cm, towards the item half of the time
    const goal = toBase(pose, [it.x, it.y, it.z]);
    const d = r() < 0.5 ? goal.map((g, k) => (g - tool[k]) * 0.3) : [r() - 0.5, r() - 0.5, r() - 0.5].map((v) => v * 0.12);
    const n = Math.hypot(...d);
    const dd = n > 0.06 ? d.map((v) => (v * 0.06) / n) : d;
    const m = moveTool(pose, tool, dd, j, boxes);
    if (m.hit) refused++;
    for (let s = 1; s <= 5; s++) if (armHits(pose, mix(j, m.joints, s / 5), boxes)) crossings++;
    if (armHits(pose, m.joints, boxes)) crossings++;
    accepted += m.tool !== tool ? 1 : 0;
    tool = m.tool;
    j = m.joints;
    const w = [0, 1, 2].map((k) => tool[k] - goal[k]);
    if (Math.hypot(...w) < 0.03) reached++;
  }
  out.push({ seed, solvable: !!j, accepted, refused, crossings, reached });
}
console.log(JSON.stringify(out));
"""


@pytest.fixture(scope="module")
def teleop_probe(tmp_path_factory) -> Path:
    return bundle(tmp_path_factory.mktemp("teleop"), "teleop", TELEOP)


@settings(max_examples=2, deadline=None, derandomize=True, phases=[Phase.explicit, Phase.generate])
@given(hs.lists(hs.integers(0, 2**31 - 1), min_size=10, max_size=10, unique=True))
def test_teleoperated_gripper_moves_never_take_the_arm_through_a_shelf_or_a_product(teleop_probe, seeds):
    rows = node_json(teleop_probe, {"seeds": seeds, "moves": 100})
    assert all(r["solvable"] and r["crossings"] == 0 for r in rows), rows
    assert sum(r["refused"] for r in rows) > 0  # the random moves do strike shelves and products
    assert sum(r["reached"] > 0 for r in rows) >= len(rows) // 2  # and the item is reached between them


# the outcome's animation for each outcome of the same trial: its cause, its end, and its start
OUTCOME = """
import { makeLayout } from "%(web)s/src/scene";
import { makeAisle } from "%(web)s/src/scene3d/geometry";
import { planReach } from "%(web)s/src/scene3d/arm";
import { planPath, Drive } from "%(web)s/src/scene3d/drive";
import { OutcomeAnimation } from "%(web)s/src/scene3d/outcome";
import { readFileSync } from "node:fs";

const req = JSON.parse(readFileSync(0, "utf8"));
const out = [];
for (const seed of req.seeds) for (const high of [false, true]) {
  const layout = makeLayout(seed, high);
  const aisle = makeAisle(layout, seed);
  const drive = new Drive(planPath(layout));
  const plan = planReach(drive.at(drive.duration + 1), aisle);
  const runs = {};
  for (const kind of ["success", "collision", "dropped"]) {
    const a = new OutcomeAnimation(kind, plan, aisle, seed, layout);
    const start = [];
    const dt = req.dt ?? 0.02;
    let t = 0, f = a.at(0, 0), inBin = false;
    for (; t < 40 && !f.done; t += dt) {
      f = a.at(t, dt);
      inBin ||= f.inBin;
      if (t < req.start) start.push(f.joints, f.pose);
    }
    runs[kind] = { cause: a.cause, done: f.done, t, inBin: f.inBin, item: a.item ? a.item.p : null, shove: Math.hypot(...a.shove), start: JSON.stringify(start) };
  }
  out.push({ seed, high, runs });
}
console.log(JSON.stringify(out));
"""


def test_a_failures_animation_shows_its_complexitys_cause_and_every_start_is_the_same(tmp_path):
    for row in run_in_node(tmp_path, OUTCOME, {"seeds": list(range(12)), "start": 1.0}):
        runs = row["runs"]
        assert all(r["done"] for r in runs.values()), row
        # the first second is the same whatever the outcome: it reveals nothing
        assert runs["success"]["start"] == runs["collision"]["start"] == runs["dropped"]["start"], row["seed"]
        assert runs["success"]["cause"] is None and runs["success"]["inBin"], row
        for kind in ("collision", "dropped"):
            r = runs[kind]
            assert r["cause"] == ("strike" if row["high"] else "slip"), (row["seed"], row["high"], kind, r)
            assert r["item"][2] < 0.1 and not r["inBin"], r  # the item on the floor
            if row["high"]:
                assert r["shove"] > 0.05, r  # the obstacle shoved aside


def run_in_node(tmp_path: Path, source: str, req: dict) -> list[dict]:
    """``source`` bundled for node, run with ``req`` on its stdin: what it prints (JSON)."""
    return node_json(bundle(tmp_path, "run", source), req)


# the 2-D scene's outcome animation for each outcome of the same trial, from the robot at the end
# of its reach: its cause, its end, its start, where the item and the obstacle are
OUTCOME_2D = """
import { makeLayout, AISLE_H, SHELF_DEPTH } from "%(web)s/src/scene";
import { Outcome2D } from "%(web)s/src/outcome2d";
import { readFileSync } from "node:fs";

const req = JSON.parse(readFileSync(0, "utf8"));
const out = [];
for (const seed of req.seeds) for (const high of [false, true]) {
  const runs = {};
  for (const kind of ["success", "collision", "dropped"]) {
    const layout = makeLayout(seed, high);
    const o = layout.obstacles.find((b) => b.kind !== "spill");
    const at = o ? [o.x, o.y] : null;
    const robot = { ...layout.pregrasp, heading: 0, arm: layout.reachExtension, jaw: 1, holding: false, binCount: 0, shake: 0 };
    const item = { x: layout.item.x, y: layout.item.y, z: 0, inBin: false, visible: true };
    const a = new Outcome2D(kind, layout, robot);
    const start = [];
    const dt = req.dt ?? 0.02;
    let t = 0, done = false;
    for (; t < 40 && !done; t += dt) {
      done = a.step(t, dt, robot, item);
      if (t < req.start) start.push([robot.x, robot.y, robot.arm, robot.jaw, item.x, item.y, item.inBin]);
    }
    const floor = item.y > SHELF_DEPTH && item.y < AISLE_H - SHELF_DEPTH;
    runs[kind] = { cause: a.cause, struck: a.struck, done, inBin: item.inBin, fallen: !!item.fallen, floor, binCount: robot.binCount,
                   shove: o ? Math.hypot(o.x - at[0], o.y - at[1]) : 0, start: JSON.stringify(start) };
  }
  out.push({ seed, high, runs });
}
console.log(JSON.stringify(out));
"""


def test_the_2d_scenes_failure_shows_its_complexitys_cause_and_every_start_is_the_same(tmp_path):
    for row in run_in_node(tmp_path, OUTCOME_2D, {"seeds": list(range(40)), "start": 1.0}):
        runs = row["runs"]
        assert all(r["done"] for r in runs.values()), row
        # the first second is the same whatever the outcome: it reveals nothing
        assert runs["success"]["start"] == runs["collision"]["start"] == runs["dropped"]["start"], row["seed"]
        ok = runs["success"]
        assert ok["cause"] is None and ok["inBin"] and ok["binCount"] == 1 and not ok["fallen"] and ok["shove"] == 0, row
        for kind in ("collision", "dropped"):
            r = runs[kind]
            assert r["cause"] == ("strike" if row["high"] else "slip"), (row["seed"], row["high"], kind, r)
            assert r["fallen"] and r["floor"] and not r["inBin"] and r["binCount"] == 0, r  # the item on the floor
            if row["high"]:
                assert r["struck"] in ("crate", "cart") and r["shove"] > 0.05, r  # the obstacle shoved aside


@pytest.mark.parametrize("scene", ["3d", "2d"])
def test_a_failure_strikes_the_obstacle_however_long_the_frames(tmp_path, scene):
    """A fast study or a slow frame moves the base far in one frame (at animation_speed 20 and
    a 100 ms frame, two seconds of the animation): the drive back still strikes the obstacle and the
    animation ends, where the base would pass through it and the trial never end."""
    rows = run_in_node(tmp_path, OUTCOME if scene == "3d" else OUTCOME_2D, {"seeds": list(range(12)), "start": 0, "dt": 2.0})
    for row in rows:
        runs = row["runs"]
        assert all(r["done"] for r in runs.values()), (row["seed"], row["high"], {k: r["cause"] for k, r in runs.items()})
        if row["high"]:
            assert runs["collision"]["cause"] == runs["dropped"]["cause"] == "strike", row
