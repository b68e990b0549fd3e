// Keyboard and gamepad (standard mapping) input for teleoperation and intervention.
//   drive base:   arrow keys / WASD          | left stick
//   arm:          Z extend, X retract         | right stick up/down
//   grasp:        G                          | A (button 0)
//   deposit:      B                          | B (button 1)
//   intervene:    Space                      | X (button 2) or RB (button 5)

export interface Command {
  vx: number; vy: number; arm: number; grasp: boolean; deposit: boolean; intervene: boolean;
  /** the device that asked to intervene this frame (logged as the intervention's `via`) */
  interveneVia: "key" | "gamepad" | null;
}

const held = new Set<string>();
const pressed = new Set<string>();
let prevButtons: boolean[] = [];

/** Whether the key belongs to the focused control (a checkbox, a button, a slider, a radio
 * group, a link): then the browser's own handling applies and the robot ignores the key. */
export function ownedByControl(target: EventTarget | null, key: string): boolean {
  if (!(target instanceof HTMLElement)) return false;
  if (target.isContentEditable || target instanceof HTMLTextAreaElement || target instanceof HTMLSelectElement) return true;
  if (target instanceof HTMLInputElement) return true; // text, checkbox, radio, range: every key is theirs
  if (target instanceof HTMLButtonElement || target instanceof HTMLAnchorElement) return key === " " || key === "Enter";
  return false;
}

export function installKeyboard(target: Window, active: () => boolean = () => true) {
  target.addEventListener("keydown", (e) => {
    const k = e.key.length === 1 ? e.key.toLowerCase() : e.key;
    if (ownedByControl(e.target, k)) return;
    // the page does not scroll under the robot's controls, but only while the robot is on screen
    if (active() && ["ArrowUp", "ArrowDown", "ArrowLeft", "ArrowRight", " "].includes(k)) e.preventDefault();
    if (!held.has(k)) pressed.add(k);
    held.add(k);
  });
  target.addEventListener("keyup", (e) => held.delete(e.key.length === 1 ? e.key.toLowerCase() : e.key));
  target.addEventListener("blur", () => held.clear());
}

export function gamepadName(): string | null {
  const pads = navigator.getGamepads ? navigator.getGamepads() : [];
  for (const p of pads) if (p && p.connected) return p.id;
  return null;
}

/** The command of this frame; edge-triggered actions fire once per press. */
export function poll(): Command {
  const h = (k: string) => held.has(k);
  const once = (...ks: string[]) => ks.some((k) => pressed.has(k));
  const cmd: Command = {
    vx: (h("ArrowRight") || h("d") ? 1 : 0) - (h("ArrowLeft") || h("a") ? 1 : 0),
    vy: (h("ArrowDown") || h("s") ? 1 : 0) - (h("ArrowUp") || h("w") ? 1 : 0),
    arm: (h("z") ? 1 : 0) - (h("x") ? 1 : 0),
    grasp: once("g"),
    deposit: once("b"),
    intervene: once(" "),
    interveneVia: null,
  };
  if (cmd.intervene) cmd.interveneVia = "key";
  pressed.clear();
  const pads = navigator.getGamepads ? navigator.getGamepads() : [];
  for (const p of pads) {
    if (!p || !p.connected) continue;
    const dz = (v: number) => (Math.abs(v) < 0.15 ? 0 : v);
    cmd.vx += dz(p.axes[0] ?? 0);
    cmd.vy += dz(p.axes[1] ?? 0);
    cmd.arm += -dz(p.axes[3] ?? 0);
    const b = p.buttons.map((x) => x.pressed);
    const edge = (i: number) => !!b[i] && !prevButtons[i];
    cmd.grasp ||= edge(0);
    cmd.deposit ||= edge(1);
    if (edge(2) || edge(5)) {
      cmd.intervene = true;
      cmd.interveneVia ??= "gamepad";
    }
    prevButtons = b;
    break;
  }
  cmd.vx = Math.max(-1, Math.min(1, cmd.vx));
  cmd.vy = Math.max(-1, Math.min(1, cmd.vy));
  cmd.arm = Math.max(-1, Math.min(1, cmd.arm));
  return cmd;
}
