// The 2-D scene's animation of an autonomous trial's outcome after the reach (the outcome is the
// server's, sealed until now), with the same causes as the 3-D scene (scene3d/outcome.ts): every
// outcome starts alike (the gripper closes, the arm pulls the item back towards the bin).
// Low complexity: a success puts the item in the bin; a failure lets it slip out of the gripper
// on the way, to the floor. High complexity: the item goes in the bin, then the base sets off back
// around the obstacle; a success ends as it sets off, a failure cuts the corner: the base strikes
// the crate or the cart, which is shoved aside, and the item is thrown out of the bin to the floor.
// Pure state: the page draws it (scene.ts).

import { AISLE_H, AISLE_W, BASE_H, BASE_W, Box, Cause, ItemState, Layout, RobotState, SHELF_DEPTH, gripperPos, pathLength, pointAlong } from "./scene";

type P2 = { x: number; y: number };
const GRASP = 0.3; // the gripper closes
const PULL = 0.8; // m/s: the arm pulls the item back
const BACK_V = 1.7 * 1.4; // m/s: the drive back, faster than the approach (the robot hurries)
const FALL = 0.4; // s: an item's fall to the floor

export class Outcome2D {
  cause: Cause | null = null;
  /** what the base struck (a strike), or null */
  struck: Box["kind"] | null = null;
  /** the strike's burst, where the base met the obstacle */
  impact: { x: number; y: number; t: number } | undefined;
  private readonly obstacle: Box | null;
  private readonly back: P2[] | null = null;
  private readonly reach: number;
  private fall: { from: P2; to: P2; t0: number } | null = null;
  private inBinAt: number | null = null;
  private struckAt: number | null = null;
  private shove: P2 = { x: 0, y: 0 };
  private struckBox: P2 | null = null; // where the obstacle stood
  private checked = 0; // the drive back's time checked for a strike so far

  /** `kind`: the server's outcome (success, collision, dropped); the robot at the end of its reach. */
  constructor(readonly kind: string, readonly layout: Layout, robot: RobotState) {
    this.reach = Math.max(0.05, robot.arm);
    this.obstacle = layout.obstacles.find((o) => o.kind !== "spill") ?? null;
    if (this.obstacle) {
      const o = this.obstacle;
      const back = [{ x: robot.x, y: robot.y }, ...layout.path.slice(1, -1).reverse().map((p) => ({ ...p })), { ...layout.start }];
      if (kind !== "success") {
        // a failure cuts the corner at the obstacle: the waypoints beside it move onto its edge
        for (const q of back.slice(1, -1)) {
          if (q.x > o.x - 1.5 && q.x < o.x + o.w + 1.5) q.y = q.y < o.y ? o.y - BASE_H * 0.3 : o.y + o.h + BASE_H * 0.3;
        }
      }
      this.back = back;
    }
  }

  /** The robot, the item and the obstacle at `t` seconds of the outcome (`k`: this frame's
   * seconds); true when the animation is over. */
  step(t: number, k: number, robot: RobotState, item: ItemState): boolean {
    const failing = this.kind !== "success";
    robot.jaw = Math.max(0, 1 - t / GRASP);
    if (t >= GRASP && this.inBinAt === null && this.cause !== "slip") {
      robot.holding = true;
      robot.arm = Math.max(0, robot.arm - PULL * k);
      Object.assign(item, gripperPos(robot, this.layout.side));
      if (failing && !this.back && robot.arm < 0.3 * this.reach) {
        // low complexity: the item slips out of the gripper and falls beside the robot
        this.cause = "slip";
        robot.holding = false;
        robot.jaw = 1;
        this.drop(t, item, { x: item.x + 0.3, y: this.floorY(item.y) });
      } else if (robot.arm <= 0) {
        this.inBinAt = t;
        robot.holding = false;
        item.inBin = true;
        robot.binCount++;
      }
    }
    if (this.cause === "slip") robot.arm = Math.max(0, robot.arm - PULL * k);
    if (this.back && this.inBinAt !== null) this.driveBack(t - this.inBinAt - 0.3, robot, item, t);
    if (this.impact) this.impact.t += k;
    this.falling(t, item);
    if (this.kind === "success") return this.inBinAt !== null && t > this.inBinAt + (this.back ? 2.2 : 0.4);
    const landed = this.fall !== null && t > this.fall.t0 + FALL;
    return landed && t > (this.struckAt ?? this.fall!.t0) + 1.2;
  }

  /** The base `s` seconds into its drive back; a failure's stops where it strikes the obstacle. */
  private driveBack(s: number, robot: RobotState, item: ItemState, t: number) {
    const o = this.obstacle!;
    if (this.struckAt !== null) {
      // the obstacle slides on after the strike
      const f = 1 - Math.exp(-4 * (t - this.struckAt));
      const d = this.shove;
      o.x = this.struckBox!.x + d.x * f;
      o.y = this.struckBox!.y + d.y * f;
      return;
    }
    const L = pathLength(this.back!);
    const at = (u: number) => pointAlong(this.back!, Math.min(L, Math.max(0, u) * BACK_V));
    // a failure's drive is checked every 10 ms since the last frame: a long frame (a fast study,
    // a slow machine) does not carry the base through the obstacle
    for (let u = this.checked; this.kind !== "success" && u < s; ) {
      u = Math.min(s, u + 0.01);
      if (this.overlaps(at(u))) {
        const q = at(u - 0.05); // the base stops short
        Object.assign(robot, { x: q.x, y: q.y, heading: q.heading });
        return this.strike(robot, item, t);
      }
      this.checked = u;
    }
    const p = at(s);
    robot.x = p.x;
    robot.y = p.y;
    robot.heading = p.heading;
  }

  private strike(robot: RobotState, item: ItemState, t: number) {
    const o = this.obstacle!;
    this.cause = "strike";
    this.struck = o.kind;
    this.struckAt = t;
    this.struckBox = { x: o.x, y: o.y };
    const c = Math.cos(robot.heading), s = Math.sin(robot.heading);
    const cart = o.kind === "cart";
    const away = Math.sign(robot.y - (o.y + o.h / 2)) || 1;
    this.shove = { x: c * (cart ? 0.6 : 0.15), y: s * (cart ? 0.6 : 0.15) - away * (cart ? 0.2 : 0.05) };
    robot.shake = 1;
    this.impact = { x: Math.max(o.x, Math.min(o.x + o.w, robot.x + (c * BASE_W) / 2)), y: Math.max(o.y, Math.min(o.y + o.h, robot.y)), t: 0 };
    // thrown out of the bin, forward and to the side away from the obstacle
    item.inBin = false;
    robot.binCount = Math.max(0, robot.binCount - 1);
    this.drop(t, { x: robot.x - c * 0.25, y: robot.y - s * 0.25 }, { x: robot.x + c * 0.6, y: this.floorY(robot.y + away * 1.2) });
  }

  /** Whether the base's footprint at p overlaps the obstacle (its extent at the heading, as clampRobot). */
  private overlaps(p: { x: number; y: number; heading: number }): boolean {
    const o = this.obstacle!;
    const c = Math.abs(Math.cos(p.heading)), s = Math.abs(Math.sin(p.heading));
    const hx = (c * BASE_W + s * BASE_H) / 2, hy = (s * BASE_W + c * BASE_H) / 2;
    return p.x + hx > o.x && p.x - hx < o.x + o.w && p.y + hy > o.y && p.y - hy < o.y + o.h;
  }

  private drop(t: number, from: P2, to: P2) {
    this.fall = { from, to: { x: Math.max(0.3, Math.min(AISLE_W - 0.3, to.x)), y: to.y }, t0: t };
  }

  /** The aisle's floor nearest to y (off the shelves). */
  private floorY(y: number): number {
    return Math.max(SHELF_DEPTH + 0.25, Math.min(AISLE_H - SHELF_DEPTH - 0.25, y));
  }

  private falling(t: number, item: ItemState) {
    if (!this.fall) return;
    const u = Math.min(1, (t - this.fall.t0) / FALL);
    item.x = this.fall.from.x + (this.fall.to.x - this.fall.from.x) * u;
    item.y = this.fall.from.y + (this.fall.to.y - this.fall.from.y) * u;
    item.fallen = true;
  }
}
