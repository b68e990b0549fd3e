// The participant's teleoperation: the base drives forward and back and turns (it cannot slide
// sideways), the gripper moves in Cartesian space in the base's frame (the 3-D arm follows by
// inverse kinematics; the 2-D arm extends towards the item's shelf), G closes and opens the
// gripper, B puts the held item in the bin. A grasp needs the open gripper around the item,
// then closed. Contacts with shelves, products or obstacles push back and are logged with what
// was struck; the effort (time, distance, inputs, contacts, grasp attempts) goes with the
// `deposit` event, the time as the trial's effort_ms. The robot's state (its gripper target
// and gripper included) is kept with the trial, so that a reload resumes where it was.

import { Command, gamepadName, moves } from "../input";
import { ARM_MAX, REACH, clampRobot, gripperPos } from "../scene";
import { TOOL_V } from "../scene3d/teleop";
import { contacts, log, page, setHint } from "./state";

const V = 0.9; // m/s, full forward
const W = 1.1; // rad/s, full turn
const DEPOSIT_R = 0.85; // the gripper within this of the torso's axis is over the bin (3-D)
let v = 0, w = 0; // the base's speeds (they ramp up and down)

export function resetTeleop() {
  page.driven = 0;
  page.armTravel = 0;
  page.graspAttempts = 0;
  contacts.reset();
  page.inputs = 0;
  v = 0;
  w = 0;
}

/** The gripper's place: the 3-D grasp point, or the 2-D one at the item's height. */
export function gripper(): { x: number; y: number; z: number } {
  if (page.scene3d && page.robot.tool) {
    const g = page.scene3d.grasp();
    return { x: g[0], y: g[1], z: g[2] };
  }
  return { ...gripperPos(page.robot, page.layout.side), z: page.item.z };
}

/** One frame of teleoperation (k: seconds at the study's pace); true when the item went in the bin. */
export function teleop(cmd: Command, k: number): boolean {
  const r = page.robot;
  if (moves(cmd)) page.inputs++;
  // the base speeds up in about half a second and brakes in a tenth
  const ramp = (to: number, now: number) => now + (to - now) * Math.min(1, (Math.abs(to) < Math.abs(now) || to * now < 0 ? 25 : 6) * k);
  v = ramp(cmd.drive * V, v);
  w = ramp(cmd.turn * W, w);
  const x0 = r.x, y0 = r.y, h0 = r.heading;
  r.heading += w * k;
  r.x += Math.cos(r.heading) * v * k;
  r.y += Math.sin(r.heading) * v * k;
  let hit = clampRobot(r, page.layout);
  const mx = r.x - x0, my = r.y - y0;
  if (page.scene3d) {
    // the arm goes with the base: where a link would enter a shelf or a product, the base stays
    const armHit = page.scene3d.teleopArm(r, page.item);
    if (armHit) {
      Object.assign(r, { x: x0, y: y0, heading: h0 });
      page.scene3d.teleopArm(r, page.item);
      hit = armHit;
    }
    const t0 = [...r.tool!];
    const d = cmd.tool.map((u) => u * TOOL_V * k);
    hit = page.scene3d.teleopArm(r, page.item, d) ?? hit;
    page.armTravel += Math.hypot(r.tool![0] - t0[0], r.tool![1] - t0[1], r.tool![2] - t0[2]);
  } else {
    // the 2-D arm: the gripper's sideways input extends it towards the item's shelf
    const a0 = r.arm;
    const out = -cmd.tool[1] * Math.sign(Math.cos(r.heading) || 1) * page.layout.side;
    r.arm = Math.max(0, Math.min(ARM_MAX, r.arm + out * TOOL_V * 2 * k));
    page.armTravel += Math.abs(r.arm - a0);
  }
  touch(hit, mx || Math.cos(r.heading) * cmd.drive, my || Math.sin(r.heading) * cmd.drive);
  page.driven += Math.hypot(r.x - x0, r.y - y0);
  r.jaw = r.closed ? Math.max(r.holding ? 0.25 : 0, r.jaw - 3 * k) : Math.min(1, r.jaw + 3 * k);
  if (r.holding && !page.scene3d) Object.assign(page.item, gripperPos(r, page.layout.side));
  if (cmd.grip) grip();
  return cmd.deposit && deposit();
}

/** G: close the gripper (a grasp when it is open around the item) or open it (letting go). */
function grip() {
  const r = page.robot;
  if (r.closed) {
    r.closed = false;
    if (r.holding) {
      r.holding = false;
      if (page.scene3d) page.scene3d.release(page.item);
      log("release", { x: +page.item.x.toFixed(3), y: +page.item.y.toFixed(3), z: +page.item.z.toFixed(3) });
      setHint("You let go of the item: open gripper around it, then close (G).");
    }
    return;
  }
  r.closed = true;
  page.graspAttempts++;
  const g = gripper();
  const distance = Math.hypot(g.x - page.item.x, g.y - page.item.y, g.z - page.item.z);
  const around = page.scene3d ? page.scene3d.around(page.item) : distance <= REACH;
  if (r.jaw > 0.8 && around && !page.item.inBin) {
    r.holding = true;
    log("grasp", { by: "human" });
  } else {
    log("grasp_missed", { distance: +distance.toFixed(3), open: +r.jaw.toFixed(2) });
    setHint(r.jaw <= 0.8 ? "Open the gripper first (G), then close it around the item." : "Missed: the open gripper must be around the item before it closes.");
  }
}

/** B: the held item into the bin, when the arm is back over the base. */
function deposit(): boolean {
  const r = page.robot;
  if (!r.holding) {
    setHint("Grasp the item first: open gripper around it, then G.");
    return false;
  }
  const out = page.scene3d && r.tool ? Math.hypot(r.tool[0], r.tool[1]) > DEPOSIT_R : r.arm > 0.3;
  if (out) {
    log("deposit_refused", { arm: +r.arm.toFixed(3) });
    setHint("Bring the gripper back over the robot (K or J/L) before depositing.");
    return false;
  }
  r.holding = false;
  r.closed = false;
  page.item.inBin = true;
  r.binCount++;
  log("deposit", {
    seconds: (performance.now() - page.teleopStart) / 1000, driven_m: +page.driven.toFixed(3), arm_m: +page.armTravel.toFixed(3),
    grasp_attempts: page.graspAttempts, contacts: contacts.count, inputs: page.inputs, gamepad: gamepadName(),
  });
  return true;
}

/** A contact begins: logged with what was struck; the base is pushed back against its motion. */
function touch(hit: string | null, mx: number, my: number) {
  if (contacts.touch(hit, page.clock, page.robot, page.layout, mx, my)) {
    const g = gripper();
    log("contact", {
      with: hit, x: +page.robot.x.toFixed(3), y: +page.robot.y.toFixed(3), heading: +page.robot.heading.toFixed(3),
      gripper: [+g.x.toFixed(3), +g.y.toFixed(3), +g.z.toFixed(3)],
    });
    if (page.scene3d) page.robot.shake = 0.6;
    if (page.scene3d && !hit!.startsWith("arm")) page.scene3d.teleopArm(page.robot, page.item);
  }
}
