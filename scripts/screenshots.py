"""Regenerate the screenshots of the participant's supervision scene in docs/experiments.md:
run tests/web/test_browser_scene.py at 1280 x 720 with the detail of a desktop (quality tier 3),
save its screenshots under docs/img/scene/, and rewrite the section between the markers
``<!-- scene screenshots -->`` and ``<!-- /scene screenshots -->``.

    .venv/bin/python scripts/screenshots.py
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
IMG = ROOT / "docs" / "img" / "scene"
DOC = ROOT / "docs" / "experiments.md"
# (file stem, caption), in the order of a trial
SHOTS = [
    ("approach", "The robot on its way to the item along its planned path (dashed)"),
    ("reach", "The arm reaches into the shelf at the item's height (local view over the robot's shoulder)"),
    ("success", "A success: the item is in the bin"),
    ("failure-low-start", "A low-complexity failure: the item slips out of the gripper on its way to the bin"),
    ("failure-low", "After the failure of a low-complexity trial: the item is on the floor in every view"),
    ("failure-high-start", "A high-complexity failure: driving back, the base strikes the obstacle in its way"),
    ("failure-high", "After the failure of a high-complexity trial: the obstacle shoved aside, the item on the floor"),
    ("intervention", "The participant intervened and drives the robot"),
    ("teleop-grasp", "Teleoperation: the open gripper around the item before it closes (wrist camera, right)"),
    ("ask", "The robot asks for help"),
    ("fallback-2d", "The 2-D scene, where the browser has no WebGL"),
    ("fallback-2d-failure-low", "A low-complexity failure in the 2-D scene: the item slipped out of the gripper, on the floor"),
    (
        "fallback-2d-failure-high",
        "A high-complexity failure in the 2-D scene: the base struck the obstacle, the item on the floor",
    ),
]
BEGIN, END = "<!-- scene screenshots -->", "<!-- /scene screenshots -->"


def main() -> int:
    IMG.mkdir(parents=True, exist_ok=True)
    for f in IMG.glob("scene-*.jpg"):
        f.unlink()
    env = {**os.environ, "TRUSTSEEK_ARTIFACTS": str(IMG), "TRUSTSEEK_SCENE_SHOTS": "1"}
    cmd = [sys.executable, "-m", "pytest", "-q", "-n", "0", "-p", "no:cacheprovider", "tests/web/test_browser_scene.py"]
    if subprocess.run(cmd, cwd=ROOT, env=env).returncode != 0:
        print("the scene tests failed: docs/experiments.md is left as it was", file=sys.stderr)
        return 1
    rows = []
    for stem, caption in SHOTS:
        f = IMG / f"scene-{stem}.jpg"
        if f.exists():
            rows.append(f"![{caption}](img/scene/{f.name})\n*{caption}.*\n")
    text = DOC.read_text()
    if BEGIN not in text or END not in text:
        print(f"{DOC}: the markers {BEGIN} and {END} are missing", file=sys.stderr)
        return 2
    body = "\n".join(rows)
    DOC.write_text(re.sub(re.escape(BEGIN) + ".*?" + re.escape(END), lambda _: f"{BEGIN}\n{body}\n{END}", text, flags=re.S))
    print(f"{len(rows)} screenshots in {IMG.relative_to(ROOT)}; {DOC.relative_to(ROOT)} updated")
    return 0


if __name__ == "__main__":
    sys.exit(main())
