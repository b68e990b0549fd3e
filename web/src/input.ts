// Keyboard and gamepad (standard mapping) input for teleoperation and intervention.
//   drive the base:       ↑/W forward, ↓/S back, ←/A ⟲ turn left, →/D turn right | left stick
//   move the gripper:     I/K forward/back, J/L left/right (the base's frame)    | right stick
//                         R/F up/down                                            | D-pad up/down, LB/LT
//   close/open gripper:   G                                                      | A (button 0)
//   deposit in the bin:   B                                                      | B (button 1)
//   intervene:            Space                                                  | X (button 2) or RB (button 5)

export interface Command {
  /** the base: forward speed and turn rate (counter-clockwise), each -1..1 */
  drive: number; turn: number;
  /** the gripper's velocity in the base's frame (forward, left, up), each -1..1 */
  tool: [number, number, number];
  /** close an open gripper, open a closed one (once per press) */
  grip: boolean;
  deposit: boolean; intervene: boolean;
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

const clamp1 = (v: number) => Math.max(-1, Math.min(1, v));

/** The command of this frame; edge-triggered actions fire once per press. */
export function poll(): Command {
  const h = (...ks: string[]) => (ks.some((k) => held.has(k)) ? 1 : 0);
  const once = (...ks: string[]) => ks.some((k) => pressed.has(k));
  const cmd: Command = {
    drive: h("ArrowUp", "w") - h("ArrowDown", "s"),
    turn: h("ArrowLeft", "a") - h("ArrowRight", "d"),
    tool: [h("i") - h("k"), h("j") - h("l"), h("r") - h("f")],
    grip: once("g"),
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
    const b = p.buttons.map((x) => x.pressed);
    cmd.drive += -dz(p.axes[1] ?? 0);
    cmd.turn += -dz(p.axes[0] ?? 0);
    cmd.tool[0] += -dz(p.axes[3] ?? 0);
    cmd.tool[1] += -dz(p.axes[2] ?? 0);
    cmd.tool[2] += (b[12] || b[4] ? 1 : 0) - (b[13] || b[6] ? 1 : 0);
    const edge = (i: number) => !!b[i] && !prevButtons[i];
    cmd.grip ||= edge(0);
    cmd.deposit ||= edge(1);
    if (edge(2) || edge(5)) {
      cmd.intervene = true;
      cmd.interveneVia ??= "gamepad";
    }
    prevButtons = b;
    break;
  }
  cmd.drive = clamp1(cmd.drive);
  cmd.turn = clamp1(cmd.turn);
  cmd.tool = cmd.tool.map(clamp1) as [number, number, number];
  return cmd;
}

/** Whether the command moves anything (an input frame of the teleoperation's effort). */
export function moves(cmd: Command): boolean {
  return !!(cmd.drive || cmd.turn || cmd.tool[0] || cmd.tool[1] || cmd.tool[2]);
}
