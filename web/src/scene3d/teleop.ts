// Teleoperation of the arm in Cartesian space: the participant moves the gripper's target in
// the base's frame (forward, left, up from the torso's axis), the arm follows it by inverse
// kinematics with the gripper level and the elbow up. A move is taken in steps of at most 1 cm,
// each checked against the shelf boards and the products: the gripper stops at the last clear
// step (what it would strike is returned), and where the arm cannot reach it stops at the
// limit. Pure geometry, checked in node.

import { Joints, LIFT_MAX, LIFT_MIN, Pose, TORSO_X, armHits, forward, inverse } from "./arm";
import { AISLE_H, SHELF_DEPTH } from "../scene";
import { Aabb, Aisle3, LEVELS } from "./geometry";

export type V3 = [number, number, number];

export const TOOL_V = 0.35;   // m/s, the gripper at full deflection
const STEP = 0.01;            // the longest step checked (m)
const JUMP = 0.2;             // the largest joint change of one step (rad): no flips
/** The gripper's target when teleoperation starts from the stowed arm: level, ahead of the torso. */
export const READY: V3 = [0.75, 0, 0.95];

export function toWorld(p: Pose, t: readonly number[]): V3 {
  const c = Math.cos(p.heading), s = Math.sin(p.heading);
  return [p.x + c * (TORSO_X + t[0]) - s * t[1], p.y + s * (TORSO_X + t[0]) + c * t[1], t[2]];
}

export function toBase(p: Pose, w: readonly number[]): V3 {
  const c = Math.cos(p.heading), s = Math.sin(p.heading);
  const dx = w[0] - p.x, dy = w[1] - p.y;
  return [c * dx + s * dy - TORSO_X, -s * dx + c * dy, w[2]];
}

/** The arm's joints that put the grasp point at the target (null: out of reach). */
export function solve(p: Pose, tool: readonly number[], jaw: number): Joints | null {
  const lift = Math.max(LIFT_MIN, Math.min(LIFT_MAX, tool[2] + 0.3));
  return inverse(p, toWorld(p, tool), 0, lift, jaw, 1);
}

function jumps(a: Joints, b: Joints): boolean {
  const d = Math.abs(Math.atan2(Math.sin(b.yaw - a.yaw), Math.cos(b.yaw - a.yaw)));
  return Math.max(d, Math.abs(b.q1 - a.q1), Math.abs(b.q2 - a.q2), Math.abs(b.q3 - a.q3)) > JUMP;
}

/** The boxes an arm on a base at `p` can reach. */
export function nearBoxes(aisle: Aisle3, p: Pose): Aabb[] {
  return [...aisle.boards, ...aisle.products].filter((b) => b.max[0] > p.x - 1.8 && b.min[0] < p.x + 1.8);
}

export interface ToolMove { tool: V3; joints: Joints; hit: Aabb | null; limited: boolean; }

/** Move the gripper's target by `delta` (base frame) from `tool`, where the arm is at `joints`. */
export function moveTool(p: Pose, tool: V3, delta: readonly number[], joints: Joints, boxes: readonly Aabb[]): ToolMove {
  const n = Math.max(1, Math.ceil(Math.hypot(delta[0], delta[1], delta[2]) / STEP));
  let cur = tool, j = joints;
  for (let i = 1; i <= n; i++) {
    const next: V3 = [tool[0] + (delta[0] * i) / n, tool[1] + (delta[1] * i) / n, tool[2] + (delta[2] * i) / n];
    const q = solve(p, next, joints.jaw);
    if (!q || jumps(j, q)) return { tool: cur, joints: j, hit: null, limited: true };
    const hit = armHits(p, q, boxes);
    if (hit) return { tool: cur, joints: j, hit, limited: true };
    cur = next;
    j = q;
  }
  return { tool: cur, joints: j, hit: null, limited: false };
}

/** Where an item let go at `p` comes to rest: on the board under it, or on the floor. */
export function restingZ(aisle: Aisle3, p: readonly number[]): number {
  const half = aisle.item.height / 2;
  if (p[1] > SHELF_DEPTH && p[1] < AISLE_H - SHELF_DEPTH) return half;
  const below = LEVELS.filter((h) => h <= p[2] - half + 0.02);
  return (below.length ? below[below.length - 1] : 0) + half;
}

/** The grasp point of an arm configuration. */
export function graspOf(p: Pose, j: Joints): V3 {
  return forward(p, j).grasp;
}
