"""Driving the participant page by its state, not by the wall clock: the page is opened with
``?manual=1`` (its clock stops) and moved on with ``window.__scene.step(seconds, frames)``; a key
is held for as many simulated frames as the goal needs, however busy the machine is."""

from __future__ import annotations

STEP_UNTIL = """
async ({ cond, dt, frames, limit }) => {
  const f = new Function("s", "g", "return " + cond);
  for (let i = 0; i < limit; i++) {
    // drawn every 10th step and at the goal: the state is the test's, the pictures cost time
    let g = window.__scene.step(dt, frames, i % 10 === 9);
    const s = window.trustseek.state();
    if (f(s, g)) {
      g = window.__scene.step(0, 0);
      return { s, g };
    }
    await new Promise((r) => setTimeout(r, 5)); // lets the page's requests answer
  }
  return { s: window.trustseek.state(), g: window.__scene.step(0, 0), failed: true };
}
"""


def step_until(page, cond: str, dt: float = 0.04, frames: int = 5, limit: int = 600) -> dict:
    """Step the page until the JS expression ``cond`` (of ``s``, the page's state, and ``g``, the
    3-D scene's) holds; the states then."""
    r = page.evaluate(STEP_UNTIL, {"cond": cond, "dt": dt, "frames": frames, "limit": limit})
    if r.get("failed"):
        raise AssertionError(f"never reached {cond}; state {r['s']}")
    return r


def hold(page, key: str, cond: str, dt: float = 0.02, limit: int = 2000) -> dict:
    """Hold ``key`` for as many frames of ``dt`` seconds as ``cond`` needs (one frame per step)."""
    page.keyboard.down(key)
    try:
        return step_until(page, cond, dt=dt, frames=1, limit=limit)
    finally:
        page.keyboard.up(key)


# a scripted standard-mapping gamepad (an init script): window.__pad.axes and .buttons are what
# navigator.getGamepads() reports
FAKE_GAMEPAD = """
window.__pad = { axes: [0, 0, 0, 0], buttons: [] };
Object.defineProperty(Navigator.prototype, "getGamepads", {
  configurable: true,
  value: () => [{
    id: "Scripted pad (STANDARD GAMEPAD)", index: 0, connected: true, mapping: "standard",
    timestamp: performance.now(), axes: window.__pad.axes.slice(),
    buttons: Array.from({ length: 17 }, (_, i) => ({ pressed: !!window.__pad.buttons[i], touched: false, value: 0 })),
  }],
});
"""
# the keys of the keyboard's teleoperation as the gamepad's stick deflections and buttons
PAD_STICK = {"ArrowUp": (1, -1), "ArrowDown": (1, 1), "ArrowLeft": (0, -1), "ArrowRight": (0, 1), "z": (3, -1), "x": (3, 1)}
PAD_BUTTON = {"g": 0, "b": 1, " ": 2}


class Keyboard:
    def hold(self, page, key: str, cond: str, dt: float = 0.02) -> dict:
        return hold(page, key, cond, dt)

    def press(self, page, key: str) -> None:
        page.keyboard.press(key)


class Gamepad:
    def hold(self, page, key: str, cond: str, dt: float = 0.02) -> dict:
        axis, v = PAD_STICK[key]
        page.evaluate(f"window.__pad.axes[{axis}] = {v}")
        try:
            return step_until(page, cond, dt=dt, frames=1, limit=2000)
        finally:
            page.evaluate(f"window.__pad.axes[{axis}] = 0")

    def press(self, page, key: str) -> None:
        page.evaluate(f"window.__pad.buttons[{PAD_BUTTON[key]}] = true")
        step_until(page, "true", dt=0.02, frames=1, limit=1)
        page.evaluate(f"window.__pad.buttons[{PAD_BUTTON[key]}] = false")


def start(page, link: str, query: str = "?manual=1&quality=0") -> None:
    """Open the link, consent, read the instructions: the first trial starts."""
    page.goto(link + query)
    page.wait_for_selector("#screen-consent:not([hidden])")
    page.check("#agree")
    page.click("#consent-btn")
    page.wait_for_selector("#screen-instructions:not([hidden])")
    page.click("#start-btn")
    page.wait_for_function("['approach', 'teleop'].includes(window.trustseek.state().phase)")


def teleoperate(page, device: Keyboard | Gamepad | None = None) -> dict:
    """Drive to the item's shelf side (up to it: a contact), line the gripper
    up with the item, extend the arm, grasp, retract, deposit. The states at the deposit."""
    page.evaluate("window.__scene.manual(true)")  # the page's clock stops while the test drives
    try:
        return _teleoperate(page, device or Keyboard())
    finally:
        if "manual=1" not in page.url:
            page.evaluate("window.__scene.manual(false)")


def _teleoperate(page, dev: Keyboard | Gamepad) -> dict:
    s = page.evaluate("window.trustseek.state()")
    side = s["side"]
    toward = "ArrowUp" if side < 0 else "ArrowDown"
    edge = 1.6 if side < 0 else 4.4  # the base stops 5 cm from the shelf (scene.ts clampRobot)
    dev.hold(page, toward, f"Math.abs(s.robot.y - {edge}) < 0.02")  # the shelf stops the base: a contact
    for _ in range(8):  # line the gripper up with the item; correct any overshoot
        s = page.evaluate("window.trustseek.state()")
        dx = s["item"]["x"] - s["gripper"]["x"]
        dy = (s["item"]["y"] - s["gripper"]["y"]) * side  # > 0: the arm must extend further
        if abs(dx) < 0.04 and abs(dy) < 0.04:
            break
        if dx > 0.04:
            dev.hold(page, "ArrowRight", "s.gripper.x >= s.item.x - 0.03", dt=0.004)
        elif dx < -0.04:
            dev.hold(page, "ArrowLeft", "s.gripper.x <= s.item.x + 0.03", dt=0.004)
        elif dy > 0.04:
            dev.hold(page, "z", f"(s.item.y - s.gripper.y) * {side} <= 0.02", dt=0.004)
        else:
            dev.hold(page, "x", f"(s.item.y - s.gripper.y) * {side} >= -0.02", dt=0.004)
    dev.press(page, "g")
    step_until(page, "s.robot.holding", limit=20)
    dev.hold(page, "x", "s.robot.arm < 0.1")
    dev.press(page, "b")
    return step_until(page, "s.phase !== 'teleop'", limit=50)
