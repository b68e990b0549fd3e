// The animation of an autonomous trial's outcome after the reach (the outcome is the server's,
// sealed until now). Every animation starts with one of three grasps chosen from the scene seed
// (clean, regrip, slow), whatever the outcome, so its start tells nothing. A success lifts the
// item out and puts it in the bin; a collision lifts too steeply: the gripper strikes the board
// above, the item and the products beside it fall; a dropped item slips out of the jaws on the
// way to the bin and falls to the floor.

import { AISLE_H, AISLE_W, rng } from "../scene";
import { Joints, Pose, Reach, STOW, inverse, mix, reachAt } from "./arm";
import { Aisle3, BOARD, LEVELS } from "./geometry";

type V3 = [number, number, number];

/** A falling body: position, velocity, spin; it rests on the floor at height `rest`. */
export class Faller {
  spin = 0;
  constructor(public p: V3, public v: V3, public rest: number, public w = 0) {}
  step(dt: number) {
    this.v[2] -= 9.81 * dt;
    for (let i = 0; i < 3; i++) this.p[i] += this.v[i] * dt;
    this.spin += this.w * dt;
    this.p[0] = Math.max(0.1, Math.min(AISLE_W - 0.1, this.p[0]));
    this.p[1] = Math.max(0.1, Math.min(AISLE_H - 0.1, this.p[1]));
    if (this.p[2] <= this.rest) {
      this.p[2] = this.rest;
      this.v = [this.v[0] * 0.6, this.v[1] * 0.6, Math.abs(this.v[2]) > 0.5 ? -this.v[2] * 0.25 : 0];
      this.w *= 0.6;
    }
  }
  get resting(): boolean {
    return this.p[2] <= this.rest + 1e-6 && Math.hypot(...this.v) < 0.05;
  }
}

export type Cause = "strike" | "slip";
export interface Held { joints: Joints; holding: boolean; item: V3; }

const ease = (t: number) => (t <= 0 ? 0 : t >= 1 ? 1 : t * t * (3 - 2 * t));

export class OutcomeAnimation {
  readonly variant: 0 | 1 | 2;
  readonly lag: number; // the extra time the grasp variant takes
  cause: Cause | null = null;
  item: Faller | null = null;
  products = new Map<number, Faller>();
  private strikeAt = -1;
  private bin: Joints;

  constructor(readonly kind: string, readonly plan: Reach, readonly aisle: Aisle3, seed: number) {
    this.variant = Math.floor(rng((seed ^ 0x2545f491) >>> 0)() * 3) as 0 | 1 | 2;
    this.lag = [0, 0.45, 0.3][this.variant];
    const p = plan.pose;
    const c = Math.cos(p.heading), s = Math.sin(p.heading);
    // over the bin, behind the torso, pointing down
    this.bin = inverse(p, [p.x - c * 0.25, p.y - s * 0.25, 0.75], -Math.PI / 2, 0.9, 0) ?? { ...STOW, jaw: 0 };
  }

  private grasp(t: number): Joints {
    const j = reachAt(this.plan, 1);
    let jaw = 1 - ease(t / 0.3);
    if (this.variant === 1 && t > 0.3) jaw = t < 0.5 ? ease((t - 0.3) / 0.2) * 0.5 : 0.5 - 0.5 * ease((t - 0.5) / 0.25);
    return { ...j, jaw };
  }

  /** The arm at time t (s) of the outcome; the held item's place; whether the animation is over. */
  at(t: number, dt: number): Held & { done: boolean } {
    const g = 0.35 + this.lag; // the grasp is over
    const slow = this.variant === 2 ? 1.4 : 1;
    const it = this.plan.target;
    const out = this.plan.preTarget;
    const lift = (u: number, up: number) => inverse(this.plan.pose, [it[0] + (out[0] - it[0]) * u, it[1] + (out[1] - it[1]) * u, it[2] + up], 0, this.plan.lift, 0);
    let joints: Joints;
    let holding = true;
    if (t < g) return { joints: this.grasp(t), holding: t > 0.3, item: [...it] as V3, done: false };
    const u = ease((t - g) / (0.7 * slow));
    if (this.kind === "collision") {
      // the gripper rises too steeply on the way out and strikes the board above
      const above = (LEVELS[this.aisle.item.level + 1] ?? 1.75) - BOARD - it[2] - 0.04;
      const up = Math.min(above, 0.04 + u * 0.6);
      joints = lift(Math.min(u, 0.35), up) ?? reachAt(this.plan, 1);
      if (up >= above && this.strikeAt < 0) this.strike(t, joints);
      if (this.strikeAt >= 0) {
        holding = false;
        joints = mix(joints, { ...STOW, jaw: 1 }, ease((t - this.strikeAt - 0.3) / 0.8));
      }
    } else {
      joints = (u < 1 ? lift(u, 0.03 * Math.min(1, u * 4)) : null) ?? this.plan.pre;
      const v = ease((t - g - 0.7 * slow) / 0.8);
      if (v > 0) joints = mix({ ...this.plan.pre, jaw: 0 }, this.bin, v);
      if (this.kind === "dropped" && v > 0.3) {
        holding = false;
        if (!this.cause) this.cause = "slip";
        joints = { ...joints, jaw: Math.min(1, (v - 0.3) * 3) };
      }
      if (this.kind === "success" && v >= 1) holding = false;
    }
    this.stepFallers(dt);
    const settled = (this.item?.resting ?? false) && [...this.products.values()].every((f) => f.resting);
    const done = this.kind === "success" ? t > g + 0.7 * slow + 1.0 : this.cause !== null && settled && t > g + 1.6;
    return { joints, holding, item: [...it] as V3, done };
  }

  /** Drop the held item from `from` (called once, when the jaws let go). */
  release(from: V3, push: V3) {
    if (!this.item) this.item = new Faller([...from] as V3, push, this.aisle.item.height / 2, 3);
  }

  private strike(t: number, _j: Joints) {
    this.strikeAt = t;
    this.cause = "strike";
    const it = this.aisle.item;
    const out = Math.sign(this.plan.preTarget[1] - it.y);
    const r = rng(Math.floor(it.x * 1000));
    // the products beside the item on its board and on the board above, or at least the nearest
    const near = this.aisle.products
      .map((p, i) => ({ p, i, dx: Math.abs((p.min[0] + p.max[0]) / 2 - it.x), lv: LEVELS.indexOf(p.min[2]) }))
      .filter(({ p, lv }) => Math.sign(it.y - this.aisle.front) === Math.sign((p.min[1] + p.max[1]) / 2 - this.aisle.front) && (lv === it.level || lv === it.level + 1))
      .sort((a, b) => a.dx - b.dx);
    for (const { p, i } of near.filter((n, k) => k === 0 || n.dx < 0.5)) {
      const h = p.max[2] - p.min[2];
      const c: V3 = [(p.min[0] + p.max[0]) / 2, (p.min[1] + p.max[1]) / 2, (p.min[2] + p.max[2]) / 2];
      this.products.set(i, new Faller(c, [(r() - 0.5) * 0.8, out * (0.9 + r()), 0.5 * r()], h / 2, (r() - 0.5) * 8));
    }
  }

  private stepFallers(dt: number) {
    // small steps, so that a long frame does not tunnel through the floor
    const n = Math.max(1, Math.ceil(dt / 0.01));
    for (let k = 0; k < n; k++) {
      this.item?.step(dt / n);
      for (const f of this.products.values()) f.step(dt / n);
    }
  }

  /** The pose of the base is the reach's. */
  get pose(): Pose {
    return this.plan.pose;
  }
}
