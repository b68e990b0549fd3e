"""Driving the participant page by its state, not by the wall clock: the page is opened with
``?manual=1`` (its clock stops) and moved on with ``window.__scene.step(seconds, frames)``; a key
is held for as many simulated frames as the goal needs, however busy the machine is."""

from __future__ import annotations

import math

STEP_UNTIL = """
async ({ cond, dt, frames, limit }) => {
  const f = new Function("s", "g", "return " + cond);
  // a task of its own (a message, not a timer: no clamping to 4 ms), so that the page's answers
  // from the server are handled between two steps
  const yieldTask = () => new Promise((r) => { const c = new MessageChannel(); c.port1.onmessage = () => r(); c.port2.postMessage(0); });
  const t0 = performance.now();
  for (let i = 0; i < limit; i++) {
    // drawn every 40th step and at the goal: the state is the test's, the pictures cost time
    let g = window.__scene.step(dt, frames, i % 40 === 39);
    const s = window.trustseek.state();
    if (f(s, g)) {
      g = window.__scene.step(0, 0);
      return { s, g };
    }
    if (s.saving || s.phase === "loading") {
      // the page waits for the server: its clock is not what it waits for (up to 60 s)
      if (performance.now() - t0 > 60000) break;
      i--;
      await new Promise((r) => setTimeout(r, 20));
    } else await yieldTask();
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
PAD_STICK = {
    "ArrowUp": (1, -1),
    "ArrowDown": (1, 1),
    "ArrowLeft": (0, -1),
    "ArrowRight": (0, 1),  # drive, turn
    "i": (3, -1),
    "k": (3, 1),
    "j": (2, -1),
    "l": (2, 1),  # the gripper forward/back, left/right
}
PAD_BUTTON = {"g": 0, "b": 1, " ": 2, "r": 12, "f": 13}


class Keyboard:
    def hold(self, page, key: str, cond: str, dt: float = 0.02) -> dict:
        return hold(page, key, cond, dt)

    def press(self, page, key: str) -> None:
        page.keyboard.press(key)


class Gamepad:
    def hold(self, page, key: str, cond: str, dt: float = 0.02) -> dict:
        if key in PAD_BUTTON:  # the D-pad moves the gripper up and down
            set_, unset = f"window.__pad.buttons[{PAD_BUTTON[key]}] = true", f"window.__pad.buttons[{PAD_BUTTON[key]}] = false"
        else:
            axis, v = PAD_STICK[key]
            set_, unset = f"window.__pad.axes[{axis}] = {v}", f"window.__pad.axes[{axis}] = 0"
        page.evaluate(set_)
        try:
            return step_until(page, cond, dt=dt, frames=1, limit=2000)
        finally:
            page.evaluate(unset)

    def press(self, page, key: str) -> None:
        page.evaluate(f"window.__pad.buttons[{PAD_BUTTON[key]}] = true")
        step_until(page, "true", dt=0.02, frames=1, limit=1)
        page.evaluate(f"window.__pad.buttons[{PAD_BUTTON[key]}] = false")


class Paced:
    """A device whose holds step frames of ``scale`` times the asked length."""

    def __init__(self, device: Keyboard | Gamepad, scale: float):
        self.device, self.scale = device, scale

    def hold(self, page, key: str, cond: str, dt: float = 0.02) -> dict:
        return self.device.hold(page, key, cond, dt * self.scale)

    def press(self, page, key: str) -> None:
        self.device.press(page, key)


def start(page, link: str, query: str = "?manual=1&quality=0") -> None:
    """Open the link, consent, read the instructions: the first trial starts."""
    page.goto(link + query)
    page.wait_for_selector("#screen-consent:not([hidden])")
    page.check("#agree")
    page.click("#consent-btn")
    page.wait_for_selector("#screen-instructions:not([hidden])")
    page.click("#start-btn")
    page.wait_for_function("['approach', 'teleop'].includes(window.trustseek.state().phase)")


def teleoperate(page, device: Keyboard | Gamepad | None = None, at_grasp=None) -> dict:
    """Drive along the robot's planned path to its place in front of the item (turning on the
    spot, then forward), push the gripper into the shelf beside the item (a contact), bring it to
    the item's height and in front of it, into the shelf around the item, close the gripper,
    pull back over the base, deposit (``at_grasp(page)`` is called before the gripper closes).
    The states at the deposit."""
    page.evaluate("window.__scene.manual(true)")  # the page's clock stops while the test drives
    try:
        # above 3 times the participant's pace, frames as short as at 3 times: a faster study
        # moves the robot as far in a frame, and its goals are reached as precisely
        speed = page.evaluate("window.trustseek.state().speed")
        return _teleoperate(page, Paced(device or Keyboard(), min(1.0, 3.0 / speed)), at_grasp)
    finally:
        if "manual=1" not in page.url:
            page.evaluate("window.__scene.manual(false)")


def settle(page) -> dict:
    """A few frames without input: the base's speeds ramp down."""
    return step_until(page, "false || true", dt=0.02, frames=30, limit=1)["s"]


WRAP = "(a => Math.atan2(Math.sin(a), Math.cos(a)))"


def turn_to(page, dev: Paced, heading: float) -> dict:
    for _ in range(12):
        s = settle(page)
        err = math.atan2(math.sin(heading - s["robot"]["heading"]), math.cos(heading - s["robot"]["heading"]))
        if abs(err) < 0.015:
            return s
        key = "ArrowLeft" if err > 0 else "ArrowRight"
        sign = 1 if err > 0 else -1
        dev.hold(page, key, f"{WRAP}({heading} - s.robot.heading) * {sign} < 0.01", dt=0.005)
    raise AssertionError(f"could not turn to {heading}: {settle(page)['robot']}")


def drive_to(page, dev: Paced, x: float, y: float) -> dict:
    for _ in range(6):
        s = settle(page)
        r = s["robot"]
        d = math.hypot(x - r["x"], y - r["y"])
        if d < 0.12:
            return s
        turn_to(page, dev, math.atan2(y - r["y"], x - r["x"]))
        # forward until the goal is no longer ahead
        dev.hold(
            page,
            "ArrowUp",
            f"(({x} - s.robot.x) * Math.cos(s.robot.heading) + ({y} - s.robot.y) * Math.sin(s.robot.heading)) < 0.03",
            dt=0.01,
        )
    return settle(page)


def tool_to(page, dev: Paced, axis: str, goal: str, tol: float = 0.015) -> dict:
    """Move the gripper along one axis of the base ("x" forward, "y" left, "z" up) until the JS
    expression ``goal`` (the signed error along it) is within ``tol``."""
    keys = {"x": ("i", "k"), "y": ("j", "l"), "z": ("r", "f")}[axis]
    for _ in range(8):
        s = settle(page)
        err = page.evaluate(f"(s => {goal})(window.trustseek.state())")
        if abs(err) < tol:
            return s
        key = keys[0] if err > 0 else keys[1]
        sign = 1 if err > 0 else -1
        dev.hold(page, key, f"({goal}) * {sign} < {tol / 2}", dt=0.004)
    raise AssertionError(f"gripper never reached {goal} along {axis}: {settle(page)}")


def _teleoperate(page, dev: Paced, at_grasp=None) -> dict:
    s = settle(page)
    side = s["side"]
    # along the planned path, from the first point ahead of the base, to its place before the item
    for p in [q for q in s["path"] if q["x"] > s["robot"]["x"] + 0.3]:
        drive_to(page, dev, p["x"], p["y"])
    s = turn_to(page, dev, 0.0)
    contacts = s["contacts"]
    # the gripper towards the shelf at the height of the board under the item: it stops at
    # what it strikes (a contact)
    tool_to(page, dev, "z", "s.item.z - 0.095 - s.gripper.z")
    out = "l" if side < 0 else "j"
    dev.hold(page, out, f"s.contacts > {contacts}", dt=0.01)
    back = "j" if side < 0 else "l"
    dev.hold(page, back, f"Math.abs(s.gripper.y - {s['robot']['y']}) < 0.5", dt=0.01)
    # base frame: x forward (the aisle at heading 0), y left, z up
    tool_to(page, dev, "z", "s.item.z - s.gripper.z")
    tool_to(page, dev, "x", "s.item.x - s.gripper.x")
    tool_to(page, dev, "y", "s.item.y - s.gripper.y", tol=0.03)
    if at_grasp:
        step_until(page, "true", frames=1, limit=1)  # drawn
        at_grasp(page)
    dev.press(page, "g")
    step_until(page, "s.robot.holding", limit=20)
    dev.hold(page, back, "s.robot.arm < 0.12", dt=0.01)
    dev.press(page, "b")
    return step_until(page, "s.phase !== 'teleop'", limit=50)
