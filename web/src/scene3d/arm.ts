// The mobile manipulator's arm: a torso lift, a shoulder yaw, shoulder, elbow and wrist pitch
// joints and a two-finger gripper. Forward and inverse kinematics, the planned reach towards
// the item (torso, unfold, then straight into the shelf at the item's height) and the check
// that no link passes through a shelf board or a product along it. Pure geometry.

import { Aabb, Aisle3, capsuleHitsBox } from "./geometry";

export const TORSO_X = 0.15;   // the torso on the base, ahead of its centre
export const R0 = 0.12;        // shoulder offset from the yaw axis
export const L1 = 0.5;         // upper arm
export const L2 = 0.45;        // forearm
export const L3 = 0.5;         // wrist to the grasp point (wrist link, palm, fingers)
export const LIFT_MIN = 0.7;
export const LIFT_MAX = 1.2;
export const PRE = 0.62;       // the gripper lines up this far in front of the item before going in

export interface Pose { x: number; y: number; heading: number; }
export interface Joints { lift: number; yaw: number; q1: number; q2: number; q3: number; jaw: number; }
type V3 = [number, number, number];

/** The arm folded over the base, as it drives. */
export const STOW: Joints = { lift: 0.8, yaw: 0, q1: 1.25, q2: 2.5, q3: 0.45, jaw: 0.3 };

export interface Links {
  yawAxis: V3; shoulder: V3; elbow: V3; wrist: V3; grasp: V3; palm: V3;
  fingers: [V3, V3][];
  dir: V3; // the gripper's pointing direction
}

/** The arm's points in the world for a base pose and joint angles. */
export function forward(p: Pose, j: Joints): Links {
  const c = Math.cos(p.heading), s = Math.sin(p.heading);
  const ax: V3 = [p.x + c * TORSO_X, p.y + s * TORSO_X, j.lift];
  const a = p.heading + j.yaw;
  const u = [Math.cos(a), Math.sin(a)];
  const at = (o: V3, len: number, ang: number): V3 => [o[0] + u[0] * len * Math.cos(ang), o[1] + u[1] * len * Math.cos(ang), o[2] + len * Math.sin(ang)];
  const shoulder = at(ax, R0, 0);
  const elbow = at(shoulder, L1, j.q1);
  const a2 = j.q1 - j.q2;
  const wrist = at(elbow, L2, a2);
  const a3 = a2 + j.q3;
  const grasp = at(wrist, L3, a3);
  const palm = at(wrist, L3 - 0.1, a3);
  const tip = at(wrist, L3 + 0.05, a3);
  const half = 0.02 + 0.07 * j.jaw;
  const v = [-u[1], u[0]];
  const off = (q: V3, k: number): V3 => [q[0] + v[0] * half * k, q[1] + v[1] * half * k, q[2]];
  const fingers: [V3, V3][] = [[off(palm, 1), off(tip, 1)], [off(palm, -1), off(tip, -1)]];
  const dir: V3 = [u[0] * Math.cos(a3), u[1] * Math.cos(a3), Math.sin(a3)];
  return { yawAxis: ax, shoulder, elbow, wrist, grasp, palm, fingers, dir };
}

/** The joints that put the grasp point at `target` with the gripper pitched by `pitch`
 * (0: level, negative: down), the torso at `lift`, the elbow up (`elbow` 1) or down (-1); null
 * when out of reach. */
export function inverse(p: Pose, target: readonly number[], pitch: number, lift: number, jaw: number, elbow = 1): Joints | null {
  const c = Math.cos(p.heading), s = Math.sin(p.heading);
  const ax = [p.x + c * TORSO_X, p.y + s * TORSO_X];
  const dx = target[0] - ax[0], dy = target[1] - ax[1];
  const yaw = wrapAngle(Math.atan2(dy, dx) - p.heading);
  const r = Math.hypot(dx, dy);
  const rw = r - L3 * Math.cos(pitch) - R0;
  const hw = target[2] - L3 * Math.sin(pitch) - lift;
  const d = Math.hypot(rw, hw);
  if (d > L1 + L2 - 1e-6 || d < Math.abs(L1 - L2) + 1e-6) return null;
  const q2 = elbow * Math.acos(Math.max(-1, Math.min(1, (d * d - L1 * L1 - L2 * L2) / (2 * L1 * L2))));
  const q1 = Math.atan2(hw, rw) + Math.atan2(L2 * Math.sin(q2), L1 + L2 * Math.cos(q2));
  return { lift, yaw, q1, q2, q3: pitch - (q1 - q2), jaw };
}

export function wrapAngle(a: number): number {
  return Math.atan2(Math.sin(a), Math.cos(a));
}

export function mix(a: Joints, b: Joints, t: number): Joints {
  const m = (x: number, y: number) => x + (y - x) * t;
  return { lift: m(a.lift, b.lift), yaw: a.yaw + wrapAngle(b.yaw - a.yaw) * t, q1: m(a.q1, b.q1), q2: m(a.q2, b.q2), q3: m(a.q3, b.q3), jaw: m(a.jaw, b.jaw) };
}

const smooth = (t: number) => t * t * (3 - 2 * t);

/** The planned reach from the stowed arm to the item: the torso rises to the item's shelf, the
 * arm unfolds to a point in front of the item, then the gripper goes straight in, level. */
export interface Reach { pose: Pose; lift: number; pre: Joints; target: V3; preTarget: V3; }

export function planReach(pose: Pose, aisle: Aisle3): Reach | null {
  const it = aisle.item;
  const out = Math.sign(pose.y - it.y) || 1; // from the shelf towards the aisle
  const lift = Math.max(LIFT_MIN, Math.min(LIFT_MAX, it.z + 0.3));
  const target: V3 = [it.x, it.y, it.z];
  const preTarget: V3 = [it.x, it.y + out * PRE, it.z];
  const pre = inverse(pose, preTarget, 0, lift, 1);
  if (!pre || !inverse(pose, target, 0, lift, 1)) return null;
  return { pose, lift, pre, target, preTarget };
}

/** The arm at fraction u of the reach (0: stowed, 1: the gripper around the item). */
export function reachAt(plan: Reach, u: number): Joints {
  const k = 0.4;
  if (u <= k) return mix({ ...STOW, jaw: 1 }, plan.pre, smooth(Math.max(0, u) / k));
  const t = smooth(Math.min(1, (u - k) / (1 - k)));
  const p = plan.preTarget.map((v, i) => v + (plan.target[i] - v) * t);
  return inverse(plan.pose, p, 0, plan.lift, 1) ?? plan.pre;
}

/** The link capsules of an arm configuration: [from, to, radius]. */
export function capsules(l: Links): [V3, V3, number][] {
  return [
    [l.shoulder, l.elbow, 0.045],
    [l.elbow, l.wrist, 0.04],
    [l.wrist, l.palm, 0.035],
    ...l.fingers.map(([a, b]) => [a, b, 0.012] as [V3, V3, number]),
  ];
}

/** The first box that a link touches in configuration j, or null. */
export function armHits(pose: Pose, j: Joints, boxes: readonly Aabb[]): Aabb | null {
  const caps = capsules(forward(pose, j));
  for (const b of boxes) for (const [a, c, r] of caps) if (capsuleHitsBox(a, c, r, b)) return b;
  return null;
}

/** Check a planned reach at `samples` points: the fractions u where a link touches a shelf
 * board or a product (empty when the reach is clear). */
export function reachCollisions(plan: Reach, aisle: Aisle3, samples = 60): number[] {
  const it = aisle.item;
  // only boxes within reach of the arm need checking
  const near = [...aisle.boards, ...aisle.products].filter((b) => b.max[0] > it.x - 1.6 && b.min[0] < it.x + 1.6);
  const bad: number[] = [];
  for (let i = 0; i <= samples; i++) {
    const u = i / samples;
    if (armHits(plan.pose, reachAt(plan, u), near)) bad.push(u);
  }
  return bad;
}
