// Procedural three.js models: the aisle (floor, instanced shelf boards and products, the
// obstacles) and the mobile manipulator (wheeled base, bin, torso, arm links placed between the
// points of the kinematics in arm.ts, two-finger gripper). three.js frame: x along the aisle,
// y up, z across the aisle (the geometry's y).

import * as THREE from "three";
import { AISLE_H, AISLE_W, BASE_H, BASE_W, Layout } from "../scene";
import { Links } from "./arm";
import { Aabb, Aisle3 } from "./geometry";

/** A point of the geometry's frame (x, y across, z up) in three.js's frame. */
export const v3 = (p: readonly number[], out = new THREE.Vector3()) => out.set(p[0], p[2], p[1]);

const lambert = (color: THREE.ColorRepresentation) => new THREE.MeshLambertMaterial({ color });

function boxMatrix(b: Aabb, m = new THREE.Matrix4()): THREE.Matrix4 {
  const s = [b.max[0] - b.min[0], b.max[2] - b.min[2], b.max[1] - b.min[1]];
  return m.compose(
    new THREE.Vector3((b.min[0] + b.max[0]) / 2, (b.min[2] + b.max[2]) / 2, (b.min[1] + b.max[1]) / 2),
    new THREE.Quaternion(),
    new THREE.Vector3(s[0], s[1], s[2]),
  );
}

export interface AisleModel {
  group: THREE.Group; products: THREE.InstancedMesh; item: THREE.Mesh; path: THREE.Line;
  /** the obstacles' meshes (in the layout's order) and where they stand */
  obstacles: { mesh: THREE.Object3D; at: THREE.Vector3 }[];
}

export function buildAisle(layout: Layout, aisle: Aisle3): AisleModel {
  const group = new THREE.Group();
  const unit = new THREE.BoxGeometry(1, 1, 1);
  const floor = new THREE.Mesh(new THREE.PlaneGeometry(AISLE_W + 4, AISLE_H), lambert("#d9d3c7"));
  floor.rotation.x = -Math.PI / 2;
  floor.position.set(AISLE_W / 2, 0, AISLE_H / 2);
  floor.receiveShadow = true;
  group.add(floor);
  const boards = new THREE.InstancedMesh(unit, lambert("#9a7656"), aisle.boards.length);
  aisle.boards.forEach((b, i) => boards.setMatrixAt(i, boxMatrix(b)));
  boards.receiveShadow = true;
  group.add(boards);
  const products = new THREE.InstancedMesh(unit, lambert("#ffffff"), aisle.products.length);
  const col = new THREE.Color();
  aisle.products.forEach((p, i) => {
    products.setMatrixAt(i, boxMatrix(p));
    products.setColorAt(i, col.set(p.color));
  });
  products.castShadow = true;
  group.add(products);
  const obstacles = layout.obstacles.map((o) => {
    const mesh = obstacle(o.kind, o.x + o.w / 2, o.y + o.h / 2, o.w, o.h);
    group.add(mesh);
    return { mesh, at: mesh.position.clone() };
  });
  const it = aisle.item;
  const item = new THREE.Mesh(new THREE.CylinderGeometry(it.radius, it.radius, it.height, 16), new THREE.MeshLambertMaterial({ color: layout.item.color, emissive: layout.item.color, emissiveIntensity: 0.25 }));
  item.castShadow = true;
  group.add(item);
  const path = new THREE.Line(new THREE.BufferGeometry(), new THREE.LineDashedMaterial({ color: "#2f6fde", dashSize: 0.15, gapSize: 0.1 }));
  group.add(path);
  return { group, products, item, path, obstacles };
}

function obstacle(kind: "crate" | "cart" | "spill", cx: number, cy: number, w: number, h: number): THREE.Object3D {
  if (kind === "spill") {
    const g = new THREE.Group();
    const puddle = new THREE.Mesh(new THREE.CircleGeometry(0.5, 20), new THREE.MeshLambertMaterial({ color: "#5aa0dc", transparent: true, opacity: 0.6 }));
    puddle.rotation.x = -Math.PI / 2;
    puddle.scale.set(w, h * 0.8, 1);
    puddle.position.set(cx, 0.005, cy);
    const cone = new THREE.Mesh(new THREE.ConeGeometry(0.12, 0.45, 4), lambert("#ffcc00"));
    cone.position.set(cx + w * 0.35, 0.225, cy - h * 0.35);
    g.add(puddle, cone);
    return g;
  }
  if (kind === "crate") {
    const crate = new THREE.Mesh(new THREE.BoxGeometry(w, 0.7, h), lambert("#b0793f"));
    crate.position.set(cx, 0.35, cy);
    crate.castShadow = true;
    return crate;
  }
  // a shopping cart: a wire basket on a frame with a handle
  const g = new THREE.Group();
  const basket = new THREE.Mesh(new THREE.BoxGeometry(w, 0.45, h * 0.8), new THREE.MeshLambertMaterial({ color: "#8b949e", wireframe: true }));
  basket.position.set(cx, 0.75, cy);
  const frame = new THREE.Mesh(new THREE.BoxGeometry(w, 0.06, h * 0.8), lambert("#5b6472"));
  frame.position.set(cx, 0.2, cy);
  const handle = new THREE.Mesh(new THREE.BoxGeometry(0.05, 0.05, h), lambert("#d1495b"));
  handle.position.set(cx - w / 2 - 0.05, 1.0, cy);
  g.add(basket, frame, handle);
  g.traverse((m) => (m.castShadow = true));
  return g;
}

/** The robot: `root` follows the base pose; the arm's meshes are placed in world coordinates
 * by `poseArm` from the kinematics' points. */
export interface RobotModel {
  root: THREE.Group; arm: THREE.Group; bin: THREE.Group;
  links: THREE.Mesh[]; joints: THREE.Mesh[]; fingers: THREE.Mesh[]; palm: THREE.Mesh; torso: THREE.Mesh; head: THREE.Mesh;
}

export function buildRobot(): RobotModel {
  const root = new THREE.Group();
  const white = lambert("#f0f2f5"), dark = lambert("#3a4250"), blue = lambert("#2f6fde"), orange = lambert("#ff9f1c");
  const base = new THREE.Mesh(new THREE.BoxGeometry(BASE_W, 0.26, BASE_H), white);
  base.position.y = 0.2;
  base.castShadow = true;
  const bumper = new THREE.Mesh(new THREE.BoxGeometry(BASE_W + 0.04, 0.06, BASE_H + 0.04), dark);
  bumper.position.y = 0.09;
  const wheels = new THREE.InstancedMesh(new THREE.CylinderGeometry(0.09, 0.09, 0.06, 14), dark, 4);
  const m = new THREE.Matrix4(), q = new THREE.Quaternion().setFromEuler(new THREE.Euler(Math.PI / 2, 0, 0));
  [[-0.3, -1], [0.3, -1], [-0.3, 1], [0.3, 1]].forEach(([x, s], i) => wheels.setMatrixAt(i, m.compose(new THREE.Vector3(x, 0.09, s * (BASE_H / 2 + 0.02)), q, new THREE.Vector3(1, 1, 1))));
  const bin = new THREE.Group();
  const binBox = new THREE.Mesh(new THREE.BoxGeometry(0.32, 0.2, 0.42), blue);
  binBox.position.y = 0.43;
  const binIn = new THREE.Mesh(new THREE.BoxGeometry(0.26, 0.02, 0.36), lambert("#1c3f86"));
  binIn.position.y = 0.535;
  bin.add(binBox, binIn);
  bin.position.x = -0.25;
  const torso = new THREE.Mesh(new THREE.CylinderGeometry(0.09, 0.11, 1, 16), white);
  torso.castShadow = true;
  const head = new THREE.Mesh(new THREE.BoxGeometry(0.14, 0.1, 0.2), dark);
  root.add(base, bumper, wheels, bin, torso, head);
  const arm = new THREE.Group();
  const linkGeo = new THREE.CylinderGeometry(1, 1, 1, 12);
  const links = [0.045, 0.04, 0.035].map((r) => {
    const l = new THREE.Mesh(linkGeo, white);
    l.userData.radius = r;
    l.castShadow = true;
    return l;
  });
  const joints = [0.065, 0.06, 0.05].map((r) => {
    const j = new THREE.Mesh(new THREE.SphereGeometry(r, 12, 8), dark);
    return j;
  });
  const palm = new THREE.Mesh(new THREE.BoxGeometry(0.06, 0.06, 0.2), dark);
  const fingers = [0, 1].map(() => new THREE.Mesh(new THREE.BoxGeometry(0.02, 0.03, 1), orange));
  arm.add(...links, ...joints, palm, ...fingers);
  return { root, arm, bin, links, joints, fingers, palm, torso, head };
}

const Y = new THREE.Vector3(0, 1, 0), Z = new THREE.Vector3(0, 0, 1);
const a = new THREE.Vector3(), b = new THREE.Vector3(), d = new THREE.Vector3();

function between(mesh: THREE.Mesh, p: readonly number[], q: readonly number[], axis: THREE.Vector3, thick: number) {
  v3(p, a);
  v3(q, b);
  d.subVectors(b, a);
  const len = Math.max(1e-4, d.length());
  mesh.position.addVectors(a, b).multiplyScalar(0.5);
  mesh.quaternion.setFromUnitVectors(axis, d.normalize());
  if (axis === Y) mesh.scale.set(thick, len, thick);
  else mesh.scale.set(1, 1, len);
}

/** Place the base, torso and arm meshes for a base pose and the arm's points. */
export function poseRobot(r: RobotModel, pose: { x: number; y: number; heading: number }, lift: number, l: Links, shake: number) {
  r.root.position.set(pose.x + shake, 0, pose.y);
  r.root.rotation.y = -pose.heading;
  r.torso.position.set(0.15, (0.33 + lift) / 2, 0);
  r.torso.scale.set(1, lift - 0.33, 1);
  r.head.position.set(0.15, lift + 0.35, 0);
  const pts = [l.shoulder, l.elbow, l.wrist, l.palm];
  r.links.forEach((m, i) => between(m, pts[i], pts[i + 1], Y, m.userData.radius as number));
  r.joints.forEach((m, i) => v3(pts[i], m.position));
  between(r.palm, l.wrist, l.palm, Z, 1);
  r.palm.scale.set(1, 1, 1);
  v3(l.palm, r.palm.position);
  r.palm.quaternion.setFromUnitVectors(Z, v3(l.dir, d).normalize());
  r.fingers.forEach((m, i) => between(m, l.fingers[i][0], l.fingers[i][1], Z, 1));
}
