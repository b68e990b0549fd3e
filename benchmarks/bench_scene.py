"""Benchmark of the participant's supervision screen in headless Chromium (software WebGL,
SwiftShader, on this machine's cores): frames per second of the whole screen at 1280 x 720
while the robot drives, draw calls per view (three.js ``renderer.info``) and the gzipped size
of the page's script.

The baseline is the 2-D scene (``?scene=2d``), measured in the same run; the 3-D scene is
measured at each quality tier (0: half resolution; 2: full; 3: with shadows; 4: antialiased
too) and with the tier it picks itself from the frame time. Frames are counted by the page's
own requestAnimationFrame loop over a few seconds of wall time.

Targets: at least 15 frames per second in software rendering, at most 60 draw calls per view,
the script at most 400 KB gzipped.

    python benchmarks/bench_scene.py [--seconds 4]
"""

from __future__ import annotations

import argparse
import gzip
import os
import sys
import tempfile
from pathlib import Path

from trustseek.client import Client
from trustseek.server.app import STATIC
from trustseek.testing.browser import launch_chromium
from trustseek.testing.servers import ThreadServer

TOKEN = "bench-scene-token"
COUNT_FRAMES = """
async (ms) => {
  let n = 0;
  const t0 = performance.now();
  await new Promise((done) => { const f = () => { n++; performance.now() - t0 < ms ? requestAnimationFrame(f) : done(); }; requestAnimationFrame(f); });
  return { fps: (n * 1000) / (performance.now() - t0), scene: window.__scene.state() };
}
"""


def measure(browser, link: str, query: str, seconds: float) -> dict:
    page = browser.new_page(viewport={"width": 1280, "height": 720})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(link + query)
    page.wait_for_selector("#screen-consent:not([hidden]), #screen-task:not([hidden])")
    if page.is_visible("#screen-consent"):
        page.check("#agree")
        page.click("#consent-btn")
        page.wait_for_selector("#screen-instructions:not([hidden])")
        page.click("#start-btn")
    page.wait_for_function("window.trustseek.state().phase === 'approach'")
    page.evaluate(COUNT_FRAMES, 1000)  # warm up (shaders compiled, the tier chosen)
    r = page.evaluate(COUNT_FRAMES, seconds * 1000)
    page.close()
    if errors:
        raise RuntimeError(f"the page failed: {errors[0]}")
    return r


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=4.0)
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    js = (STATIC / "participant.js").read_bytes()
    gz_kb = len(gzip.compress(js, 9)) / 1024
    print(f"machine: {os.cpu_count()} cores; headless Chromium, software WebGL (SwiftShader); 1280 x 720")
    print(f"participant.js: {len(js) / 1024:.0f} KB, {gz_kb:.0f} KB gzipped (target <= 400 KB)")
    with tempfile.TemporaryDirectory() as d, ThreadServer(f"sqlite:///{Path(d) / 'bench.sqlite'}", TOKEN) as url:
        c = Client(url, TOKEN)
        study = c.create_study(
            {"name": "bench", "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["high"] * 3}}]}
        )
        runs = (
            [("2-D scene (baseline)", "?scene=2d")]
            + [(f"3-D tier {t}", f"?quality={t}") for t in (0, 2, 3, 4)]
            + [("3-D, tier from frame time", "")]
        )
        links = [s["link"] for s in c.create_sessions(study["id"], participants=[f"b{i}" for i in range(len(runs))])]
        with sync_playwright() as p:
            browser = launch_chromium(p)
            for (name, query), link in zip(runs, links, strict=True):
                r = measure(browser, link, query, args.seconds)
                g = r["scene"]
                calls = "" if g is None else "  draw calls world/local/ee {world}/{local}/{ee}".format(**g["calls"])
                tier = "" if g is None else f"  tier {g['tier']}, {g['frameMs']:.0f} ms to draw the views"
                print(f"{name:28s} {r['fps']:5.1f} frames/s{calls}{tier}")
            browser.close()
        c.close()
    print("targets: >= 15 frames/s, <= 60 draw calls per view, <= 400 KB gzipped")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
