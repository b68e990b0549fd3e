// The animation of an autonomous trial's outcome after the reach (the outcome is the server's,
// sealed until now). Every animation starts with one of three grasps chosen from the scene seed
// (clean, regrip, slow), whatever the outcome, so its start tells nothing. A failure shows a
// cause that fits the trial's complexity. Low complexity: a success lifts the item out and puts
// it in the bin; a failure lets it slip out of the jaws on the way to the bin, to the floor.
// High complexity: the item goes in the bin, then the base sets off back around the obstacle in
// the aisle; a success ends as it sets off, a failure cuts the corner: the base strikes the
// crate or the cart, which is shoved aside, and the item is thrown out of the bin to the floor.

import { AISLE_H, AISLE_W, BASE_H, BASE_W, Box, Cause, Layout, rng } from "../scene";
import { Joints, Pose, Reach, STOW, forward, inverse, mix, reachAt } from "./arm";
import { Drive, planPath } from "./drive";
import { Aisle3 } from "./geometry";

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

export interface Held { joints: Joints; holding: boolean; item: V3; }
/** The base's pose while it drives back (high complexity), and whether the item is in the bin. */
export interface Frame extends Held { done: boolean; pose: Pose | null; inBin: boolean; }

const BACK_PACE = 1.4; // the drive back runs this much faster than the approach (the robot hurries)
const ease = (t: number) => (t <= 0 ? 0 : t >= 1 ? 1 : t * t * (3 - 2 * t));

export class OutcomeAnimation {
  readonly variant: 0 | 1 | 2;
  readonly lag: number; // the extra time the grasp variant takes
  cause: Cause | null = null;
  item: Faller | null = null;
  products = new Map<number, Faller>();
  /** high complexity: the drive back, the obstacle in its way, and how far it was shoved */
  readonly back: Drive | null = null;
  readonly obstacle: Box | null = null;
  shove: V3 = [0, 0, 0];
  private struck: { t: number; pose: Pose; v: V3 } | null = null;
  private checked = 0; // the drive back's time checked for a strike so far
  private bin: Joints;

  constructor(readonly kind: string, readonly plan: Reach, readonly aisle: Aisle3, seed: number, layout?: Layout) {
    this.variant = Math.floor(rng((seed ^ 0x2545f491) >>> 0)() * 3) as 0 | 1 | 2;
    this.lag = [0, 0.45, 0.3][this.variant];
    const p = plan.pose;
    const c = Math.cos(p.heading), s = Math.sin(p.heading);
    // over the bin, behind the torso, pointing down
    this.bin = inverse(p, [p.x - c * 0.25, p.y - s * 0.25, 0.75], -Math.PI / 2, 0.9, 0) ?? { ...STOW, jaw: 0 };
    const o = layout?.obstacles.find((b) => b.kind !== "spill");
    if (layout && o) {
      this.obstacle = o;
      const path = planPath({ ...layout, start: { x: p.x, y: p.y }, pregrasp: layout.start });
      if (kind !== "success") {
        // a failure cuts the corner at the obstacle: the waypoints beside it move onto its edge
        for (const q of path.slice(1, -1)) {
          if (q.x > o.x - 1.5 && q.x < o.x + o.w + 1.5) q.y = q.y < o.y ? o.y - BASE_H * 0.3 : o.y + o.h + BASE_H * 0.3;
        }
      }
      this.back = new Drive(path, p.heading);
    }
  }

  private grasp(t: number): Joints {
    const j = reachAt(this.plan, 1);
    let jaw = 1 - ease(t / 0.3);
    if (this.variant === 1 && t > 0.3) jaw = t < 0.5 ? ease((t - 0.3) / 0.2) * 0.5 : 0.5 - 0.5 * ease((t - 0.5) / 0.25);
    return { ...j, jaw };
  }

  /** The arm at time t (s) of the outcome; the held item's place; the base's pose while it drives
   * back; whether the animation is over. */
  at(t: number, dt: number): Frame {
    const g = 0.35 + this.lag; // the grasp is over
    const slow = this.variant === 2 ? 1.4 : 1;
    const it = this.plan.target;
    const out = this.plan.preTarget;
    const lift = (u: number, up: number) => inverse(this.plan.pose, [it[0] + (out[0] - it[0]) * u, it[1] + (out[1] - it[1]) * u, it[2] + up], 0, this.plan.lift, 0);
    if (t < g) return { joints: this.grasp(t), holding: t > 0.3, item: [...it] as V3, done: false, pose: null, inBin: false };
    const u = ease((t - g) / (0.7 * slow));
    let joints = (u < 1 ? lift(u, 0.03 * Math.min(1, u * 4)) : null) ?? this.plan.pre;
    let holding = true;
    const tb = g + 0.7 * slow; // the arm sets off for the bin
    const v = ease((t - tb) / 0.8);
    if (v > 0) joints = mix({ ...this.plan.pre, jaw: 0 }, this.bin, v);
    const slips = this.kind !== "success" && !this.back;
    if (slips && v > 0.3) {
      holding = false;
      if (!this.cause) {
        // the item slips out of the jaws and falls, a little away from the shelf
        this.cause = "slip";
        this.release(forward(this.plan.pose, joints).grasp, [0.2, Math.sign(out[1] - it[1]) * 0.3, 0]);
      }
      joints = { ...joints, jaw: Math.min(1, (v - 0.3) * 3) };
    }
    const inBin = !slips && v >= 1;
    if (inBin) holding = false;
    let pose: Pose | null = null;
    if (this.back && inBin) {
      joints = mix(this.bin, { ...STOW, jaw: 0.3 }, ease((t - tb - 0.8) / 0.6));
      pose = this.driveBack(t - tb - 1.0);
    }
    this.stepFallers(dt);
    const settled = (this.item?.resting ?? false) && [...this.products.values()].every((f) => f.resting);
    let done: boolean;
    // a success ends once the base has set off (it goes on out of the picture); a failure drives on to its strike
    if (this.kind === "success") done = this.back ? t > tb + 2.2 : t > tb + 1.8;
    else done = this.cause !== null && settled && t > (this.struck ? this.struck.t + 1.2 : g + 1.6);
    return { joints, holding, item: [...it] as V3, done, pose, inBin: inBin && !this.struck };
  }

  /** The base `s` seconds into its drive back; a failure's drive stops where it strikes the obstacle. */
  private driveBack(s: number): Pose {
    const back = this.back!;
    if (this.struck) {
      const k = Math.max(0, s - this.struck.t);
      const o = this.struck.v;
      this.shove = [o[0] * (1 - Math.exp(-4 * k)), o[1] * (1 - Math.exp(-4 * k)), 0];
      return this.struck.pose;
    }
    // a failure's drive is checked every 10 ms since the last frame: a long frame (a fast study,
    // a slow machine) does not carry the base through the obstacle
    for (let u = this.checked; this.kind !== "success" && u < s; ) {
      u = Math.min(s, u + 0.01);
      if (this.overlaps(back.at(Math.max(0, u) * BACK_PACE))) return this.strike(u);
      this.checked = u;
    }
    return back.at(Math.max(0, s) * BACK_PACE);
  }

  /** The strike `s` seconds into the drive back: the base stops short, the obstacle is shoved
   * on, the item flies out of the bin. */
  private strike(s: number): Pose {
    const back = this.back!;
    const prev = back.at(Math.max(0, s - 0.05) * BACK_PACE);
    const d = [Math.cos(prev.heading), Math.sin(prev.heading)];
    const cart = this.obstacle!.kind === "cart";
    this.struck = { t: s, pose: prev, v: [d[0] * (cart ? 0.6 : 0.15), d[1] * (cart ? 0.6 : 0.15) + (cart ? 0.2 : 0.05) * Math.sign(d[1] || 1), 0] };
    this.cause = "strike";
    const c = Math.cos(prev.heading), sn = Math.sin(prev.heading);
    const bin: V3 = [prev.x - c * 0.25, prev.y - sn * 0.25, 0.62];
    // thrown forward and out to the side away from the obstacle, where every camera sees it
    const o = this.obstacle!;
    const away = Math.sign(prev.y - (o.y + o.h / 2)) || 1;
    this.release(bin, [d[0] * 0.8, d[1] * 0.8 + away * 1.6, 1.5]);
    return prev;
  }

  /** Whether the base's footprint at p overlaps the obstacle (separating axes). */
  private overlaps(p: Pose): boolean {
    const o = this.obstacle!;
    const c = Math.cos(p.heading), s = Math.sin(p.heading);
    const corners = [[1, 1], [1, -1], [-1, -1], [-1, 1]].map(([a, b]) => [p.x + (c * a * BASE_W) / 2 - (s * b * BASE_H) / 2, p.y + (s * a * BASE_W) / 2 + (c * b * BASE_H) / 2]);
    const oc = [[o.x, o.y], [o.x + o.w, o.y], [o.x + o.w, o.y + o.h], [o.x, o.y + o.h]];
    return ![[1, 0], [0, 1], [c, s], [-s, c]].some(([ax, ay]) => {
      const pa = corners.map(([x, y]) => x * ax + y * ay), pb = oc.map(([x, y]) => x * ax + y * ay);
      return Math.max(...pa) <= Math.min(...pb) || Math.max(...pb) <= Math.min(...pa);
    });
  }

  /** Drop the held item from `from` (called once, when the jaws let go). */
  release(from: V3, push: V3) {
    if (!this.item) this.item = new Faller([...from] as V3, push, this.aisle.item.height / 2, 3);
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
