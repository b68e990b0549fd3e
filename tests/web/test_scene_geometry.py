"""The 3-D scene's geometry (web/src/scene3d/), run in node: for any scene seed and complexity,
the planned reach never brings a link of the arm into a shelf board or a product box, the base's
drive keeps its footprint out of the obstacles, accelerates from rest and turns without jumps."""

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


@pytest.fixture(scope="module")
def probe(tmp_path_factory) -> Path:
    node = shutil.which("node")
    if node is None or not ESBUILD.exists():
        pytest.fail("node and web/node_modules are needed: run scripts/setup.sh")
    d = tmp_path_factory.mktemp("probe")
    (d / "probe.ts").write_text(PROBE % {"web": WEB.as_posix()})
    cmd = [str(ESBUILD), str(d / "probe.ts"), "--bundle", "--platform=node", "--format=esm", f"--outfile={d / 'probe.mjs'}"]
    subprocess.run([*cmd, "--log-level=warning"], check=True)
    return d / "probe.mjs"


def run(probe: Path, seeds: list[int], products_out: bool = False) -> list[dict]:
    req = json.dumps({"seeds": seeds, "products_out": products_out})
    res = subprocess.run(["node", str(probe)], input=req, capture_output=True, text=True, check=True, timeout=120)
    return json.loads(res.stdout)


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
