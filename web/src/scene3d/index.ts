// The 3-D supervision scene: what the participant page asks of it. The page keeps the trial's
// flow and its 2-D state (robot, item, arm extension); this scene plans the drive and the reach,
// animates the outcome, blocks the arm where it would strike a shelf or a product, and draws
// the three views of one scene graph.

import * as THREE from "three";
import { ItemState, Layout, RobotState, View, drawPickTray } from "../scene";
import { Joints, Pose, Reach, STOW, armHits, forward, planReach, reachAt } from "./arm";
import { Drive, planPath } from "./drive";
import { Aabb, Aisle3, makeAisle } from "./geometry";
import { AisleModel, RobotModel, buildAisle, buildRobot, poseRobot, v3 } from "./models";
import { OutcomeAnimation } from "./outcome";
import { READY, moveTool, nearBoxes, restingZ, solve, toBase } from "./teleop";
import { VIEW_NAMES, ViewName, Views } from "./views";

type V3 = [number, number, number];

export class Scene3D {
  readonly scene = new THREE.Scene();
  readonly views: Views;
  private robotModel: RobotModel = buildRobot();
  private aisleModel: AisleModel | null = null;
  layout!: Layout;
  aisle!: Aisle3;
  drive!: Drive;
  plan: Reach | null = null;
  joints: Joints = { ...STOW };
  pose: Pose = { x: 0, y: 0, heading: 0 };
  anim: OutcomeAnimation | null = null;
  private seed = 0;
  private look = new THREE.Vector3(3, 0.3, 3);

  constructor(readonly canvases: Record<ViewName, HTMLCanvasElement>, tier: number | null) {
    this.scene.background = new THREE.Color("#1d2330");
    this.scene.add(new THREE.HemisphereLight("#ffffff", "#8a8070", 2.2));
    const sun = new THREE.DirectionalLight("#ffffff", 1.6);
    sun.position.set(6, 9, 2);
    sun.target.position.set(9, 0, 3);
    sun.shadow.mapSize.set(1024, 1024);
    Object.assign(sun.shadow.camera, { left: -10, right: 10, top: 6, bottom: -6 });
    this.scene.add(sun, sun.target, this.robotModel.root, this.robotModel.arm);
    this.views = new Views(this.scene, sun, tier);
    const w = this.views.cameras.world;
    w.position.set(8, 13.5, 7.6);
    w.lookAt(8, 0, 3.1);
  }

  /** A new trial: its aisle from the scene seed, the planned drive; the item at its height. */
  setTrial(layout: Layout, seed: number, item: ItemState) {
    this.layout = layout;
    this.seed = seed;
    this.aisle = makeAisle(layout, seed);
    this.drive = new Drive(planPath(layout), 0);
    const end = this.drive.at(this.drive.duration + 1);
    this.plan = planReach(end, this.aisle);
    this.anim = null;
    this.joints = { ...STOW };
    item.z = this.aisle.item.z;
    if (this.aisleModel) {
      this.scene.remove(this.aisleModel.group);
      this.aisleModel.group.traverse((o) => (o as THREE.Mesh).geometry?.dispose());
    }
    this.aisleModel = buildAisle(layout, this.aisle);
    this.scene.add(this.aisleModel.group);
    const pts = this.drive.path.map((p) => new THREE.Vector3(p.x, 0.02, p.y));
    this.aisleModel.path.geometry.setFromPoints(pts);
    this.aisleModel.path.computeLineDistances();
  }

  /** The base's pose `t` seconds into its drive, and the drive's length in seconds. */
  drivePose(t: number): Pose {
    return this.drive.at(t);
  }

  /** The outcome's animation at time t; true when it is over. Sets the page's robot and item. */
  outcome(kind: string, t: number, dt: number, robot: RobotState, item: ItemState): boolean {
    if (!this.plan) return true;
    this.anim ??= new OutcomeAnimation(kind, this.plan, this.aisle, this.seed, this.layout);
    const a = this.anim;
    const s = a.at(t, dt);
    this.joints = s.joints;
    if (s.pose) {
      this.pose = s.pose;
      Object.assign(robot, { x: s.pose.x, y: s.pose.y, heading: s.pose.heading });
      if (a.cause === "strike" && robot.shake === 0 && !a.item?.resting) robot.shake = 1;
    }
    const l = forward(this.pose, s.joints);
    robot.jaw = s.joints.jaw;
    if (s.holding) {
      robot.holding = true;
      this.setItem(item, l.grasp);
    } else if (robot.holding) {
      robot.holding = false;
      if (s.inBin) {
        item.inBin = true;
        robot.binCount++;
      }
    }
    if (a.item) {
      if (item.inBin) {
        item.inBin = false; // thrown out of the bin
        robot.binCount--;
      }
      this.setItem(item, a.item.p);
    }
    return s.done;
  }

  private setItem(item: ItemState, p: readonly number[]) {
    item.x = p[0];
    item.y = p[1];
    item.z = p[2];
  }

  /** Teleoperation: the arm where the robot's gripper target (`robot.tool`, set on the first
   * call) puts it, the target moved by `delta` (base frame, m) as far as the arm stays clear.
   * What a link would strike ("arm-shelf", "arm-product"): with `delta` zero, after the base
   * moved, the page then puts the base back; otherwise the gripper stopped short of it. */
  teleopArm(robot: RobotState, item: ItemState, delta: readonly number[] = [0, 0, 0]): string | null {
    const pose = { x: robot.x, y: robot.y, heading: robot.heading };
    const boxes = nearBoxes(this.aisle, pose);
    robot.tool ??= this.startTool(pose, boxes);
    const name = (b: Aabb) => (this.aisle.boards.includes(b) ? "arm-shelf" : "arm-product");
    const here = solve(pose, robot.tool, robot.jaw);
    const blocked = here ? armHits(pose, here, boxes) : null;
    if (!here || blocked) return blocked ? name(blocked) : "arm-limit";
    this.pose = pose;
    const m = moveTool(pose, robot.tool, delta, here, boxes);
    robot.tool = m.tool;
    this.joints = { ...m.joints, jaw: robot.jaw };
    const g = forward(pose, this.joints).grasp;
    robot.arm = Math.max(0, Math.hypot(robot.tool[0], robot.tool[1]) - 0.62);
    if (robot.holding) this.setItem(item, g);
    return m.hit ? name(m.hit) : null;
  }

  /** The gripper's target as teleoperation begins: where the arm's grasp point is, if the arm
   * can hold it level there, or ahead of the torso. */
  private startTool(pose: Pose, boxes: Aabb[]): V3 {
    const now = toBase(pose, forward(pose, this.joints).grasp);
    const j = solve(pose, now, this.joints.jaw);
    return j && !armHits(pose, j, boxes) ? now : [...READY];
  }

  /** The item let go where the gripper is: it comes to rest on the board below, or the floor. */
  release(item: ItemState) {
    const g = forward(this.pose, this.joints).grasp;
    this.setItem(item, [g[0], g[1], restingZ(this.aisle, g)]);
  }

  /** The gripper's grasp point in the world. */
  grasp(): V3 {
    return forward(this.pose, this.joints).grasp;
  }

  /** Whether the item is between the open fingers (what a grasp in teleoperation needs). */
  around(item: ItemState): boolean {
    const l = forward(this.pose, this.joints);
    const d = [item.x - l.grasp[0], item.y - l.grasp[1], item.z - l.grasp[2]];
    const along = d[0] * l.dir[0] + d[1] * l.dir[1] + d[2] * l.dir[2];
    const h = Math.hypot(l.dir[0], l.dir[1]) || 1;
    const side = (-d[0] * l.dir[1] + d[1] * l.dir[0]) / h;
    return along > -0.12 && along < 0.06 && Math.abs(side) < 0.08 && Math.abs(d[2]) < 0.06;
  }

  /** Draw the three views for the page's state in `phase`. */
  draw(v: View, phase: string) {
    const am = this.aisleModel;
    if (!am) return; // no trial yet
    const { robot, item } = v;
    this.pose = { x: robot.x, y: robot.y, heading: robot.heading };
    if (phase === "approach") this.joints = { ...STOW, jaw: robot.jaw };
    else if (phase === "reach" && this.plan) this.joints = reachAt(this.plan, Math.min(1, robot.arm / Math.max(1e-6, this.layout.reachExtension)));
    else if (phase === "waiting" && this.plan) this.joints = reachAt(this.plan, 1);
    const l = forward(this.pose, this.joints);
    poseRobot(this.robotModel, this.pose, this.joints.lift, l, robot.shake > 0 ? Math.sin(v.time * 60) * 0.03 * robot.shake : 0);
    am.path.visible = v.showPath;
    const ip = am.item.position;
    if (item.inBin) v3([robot.x - 0.25 * Math.cos(robot.heading), robot.y - 0.25 * Math.sin(robot.heading), 0.62], ip);
    else v3([item.x, item.y, item.z], ip);
    am.item.rotation.z = this.anim?.item ? this.anim.item.spin : 0;
    am.item.visible = item.visible;
    this.placeFallen(am);
    this.aimCameras(l, item, phase);
    this.views.render(this.canvases, (n, g) => this.overlay(n, g, v));
  }

  private placeFallen(am: AisleModel) {
    for (const [i, o] of am.obstacles.entries()) {
      const shoved = this.anim && this.anim.obstacle === this.layout.obstacles[i] ? this.anim.shove : [0, 0, 0];
      o.mesh.position.set(o.at.x + shoved[0], o.at.y, o.at.z + shoved[1]);
    }
    if (!this.anim) return;
    const m = new THREE.Matrix4(), q = new THREE.Quaternion(), e = new THREE.Euler();
    for (const [i, f] of this.anim.products) {
      const p = this.aisle.products[i];
      const size = new THREE.Vector3(p.max[0] - p.min[0], p.max[2] - p.min[2], p.max[1] - p.min[1]);
      am.products.setMatrixAt(i, m.compose(v3(f.p), q.setFromEuler(e.set(0, 0, f.spin)), size));
    }
    am.products.instanceMatrix.needsUpdate = true;
  }

  private aimCameras(l: ReturnType<typeof forward>, item: ItemState, phase: string) {
    const r = this.robotModel.root;
    r.updateMatrixWorld();
    // the local camera on a mast at the back of the base, over the robot's shoulder
    const head = new THREE.Vector3(-0.55, 1.75, 0).applyMatrix4(r.matrixWorld);
    const out = Math.hypot(l.grasp[0] - l.yawAxis[0], l.grasp[1] - l.yawAxis[1]) > 0.45;
    const dropped = !!this.anim?.item;
    const goal = dropped || phase === "teleop" ? v3([item.x, item.y, item.z]) : out ? v3(l.grasp) : new THREE.Vector3(3, 0.2, 0).applyMatrix4(r.matrixWorld);
    this.look.lerp(goal, phase === "approach" || dropped ? 1 : 0.25);
    const local = this.views.cameras.local;
    local.position.copy(head);
    local.lookAt(this.look);
    const ee = this.views.cameras.ee;
    const dir = v3(l.dir).normalize();
    const up = Math.abs(dir.y) > 0.95 ? v3([Math.cos(this.pose.heading), Math.sin(this.pose.heading), 0]) : new THREE.Vector3(0, 1, 0);
    ee.up.copy(up);
    ee.position.copy(v3(l.palm)).addScaledVector(dir, -0.06).addScaledVector(up, 0.07);
    // after a drop the wrist camera turns to the item on the floor
    ee.lookAt(dropped ? v3([item.x, item.y, item.z]) : ee.position.clone().add(dir));
  }

  private overlay(n: ViewName, g: CanvasRenderingContext2D, v: View) {
    if (n === "world") {
      if (v.picks) drawPickTray(g, v.picks, Math.max(0.75, Math.min(2, g.canvas.width / 900)), v.time);
      if (v.bubble) {
        const p = v3([v.robot.x, v.robot.y, 2.1]).project(this.views.cameras.world);
        const x = ((p.x + 1) / 2) * g.canvas.width, y = ((1 - p.y) / 2) * g.canvas.height;
        g.font = `bold ${Math.max(11, g.canvas.height / 22)}px system-ui, sans-serif`;
        const w = g.measureText(v.bubble).width + 16;
        g.fillStyle = "#f5a524";
        g.fillRect(x - w / 2, y - 26, w, 24);
        g.fillStyle = "#1d2330";
        g.textAlign = "center";
        g.fillText(v.bubble, x, y - 9);
      }
    }
    if (v.flash > 0) {
      g.fillStyle = `rgba(220,30,30,${0.3 * v.flash})`;
      g.fillRect(0, 0, g.canvas.width, g.canvas.height);
    }
  }

  /** What the tests and the benchmark read: the item in the world and in each view, the cause of
   * a failure, the products that fell, the draw calls per view, the quality tier. */
  state() {
    const ip = this.aisleModel ? this.aisleModel.item.position.clone() : new THREE.Vector3();
    return {
      item: [ip.x, ip.z, ip.y] as V3,
      views: this.views.project(ip),
      cause: this.anim?.cause ?? null,
      variant: this.anim?.variant ?? null,
      fallen: this.anim ? this.anim.products.size : 0,
      shoved: this.anim ? Math.hypot(this.anim.shove[0], this.anim.shove[1]) : 0,
      struck: this.anim?.cause === "strike" ? this.anim.obstacle!.kind : null,
      fallenOnFloor: this.anim ? [...this.anim.products.values()].filter((f) => f.p[2] < 0.3).length : 0,
      joints: this.joints,
      level: this.aisle?.item.level ?? null,
      drive: this.drive ? { duration: this.drive.duration, path: this.drive.path } : null,
      calls: { ...this.views.calls },
      tier: this.views.tier,
      frameMs: this.views.frameMs,
      names: VIEW_NAMES,
    };
  }
}
