// The grocery aisle: geometry, a deterministic layout per trial, and the three camera views
// (world, local, end-effector) drawn on 2D canvases.

export const AISLE_W = 16;
export const AISLE_H = 6;
export const SHELF_DEPTH = 1.2;
export const BASE_W = 0.9;
export const BASE_H = 0.7;
export const ARM_MAX = 1.4;
export const REACH = 0.42;

export interface Box { x: number; y: number; w: number; h: number; kind: "crate" | "cart" | "spill"; }
export interface Product { x: number; y: number; w: number; h: number; color: string; side: -1 | 1; }

export interface Layout {
  side: -1 | 1; // -1: item on the top shelf, +1: bottom shelf
  item: { x: number; y: number; color: string };
  obstacles: Box[];
  products: Product[];
  start: { x: number; y: number };
  pregrasp: { x: number; y: number };
  reachExtension: number;
  path: { x: number; y: number }[];
}

export interface RobotState {
  x: number; y: number;
  heading: number;   // radians, 0 = facing +x
  arm: number;       // extension towards the item's shelf, 0..ARM_MAX
  jaw: number;       // 0 closed .. 1 open
  holding: boolean;
  binCount: number;
  shake: number;     // collision shake, decays
  /** teleoperation in 3-D: the gripper's target in the base's frame (forward, left, up; m) */
  tool?: [number, number, number];
  /** teleoperation: the gripper commanded closed */
  closed?: boolean;
}

/** `fallen`: the 2-D scene's item on the floor after a failure (the 3-D scene has its height). */
export interface ItemState { x: number; y: number; z: number; inBin: boolean; visible: boolean; fallen?: boolean; }

/** What a failure's animation shows: the base strikes the obstacle (high complexity), or the
 * grasp slips (low); the same in both scenes. */
export type Cause = "strike" | "slip";

// mulberry32: a small seeded generator so a trial looks the same after a reload
export function rng(seed: number): () => number {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

const PRODUCT_COLORS = ["#e4572e", "#f3a712", "#29335c", "#669bbc", "#a8c686", "#d1495b", "#edae49", "#00798c", "#8e7dbe", "#f7b2ad"];
const ITEM_COLORS = ["#ff2d6f", "#ff7b00", "#00c2a8"];

export function makeLayout(seed: number, high: boolean): Layout {
  const r = rng(seed);
  const side: -1 | 1 = r() < 0.5 ? -1 : 1;
  const itemX = 9.5 + r() * 4.5;
  const shelfY = side < 0 ? SHELF_DEPTH * 0.62 : AISLE_H - SHELF_DEPTH * 0.62;
  const start = { x: 1.6, y: AISLE_H / 2 };
  const pregraspY = side < 0 ? SHELF_DEPTH + 0.85 : AISLE_H - SHELF_DEPTH - 0.85;
  const pregrasp = { x: itemX - 0.15, y: pregraspY };
  const reachExtension = Math.abs(pregraspY - shelfY) - BASE_H / 2;
  const products: Product[] = [];
  for (const s of [-1, 1] as const) {
    let x = 0.15;
    while (x < AISLE_W - 0.4) {
      const w = 0.28 + r() * 0.32;
      const h = 0.3 + r() * 0.5;
      const y = s < 0 ? 0.1 + r() * 0.15 : AISLE_H - 0.1 - r() * 0.15 - h;
      if (!(s === side && Math.abs(x + w / 2 - itemX) < 0.45)) {
        products.push({ x, y, w, h, color: PRODUCT_COLORS[Math.floor(r() * PRODUCT_COLORS.length)], side: s });
      }
      x += w + 0.06 + r() * 0.1;
    }
  }
  const obstacles: Box[] = [];
  const path = [start];
  if (high) {
    // an obstacle in the direct path, and a second one narrowing the detour
    const ox = 4.8 + r() * 2.2;
    obstacles.push({ x: ox - 0.5, y: AISLE_H / 2 - 0.6, w: 1.0, h: 1.2, kind: r() < 0.5 ? "crate" : "cart" });
    const detourY = side < 0 ? SHELF_DEPTH + 0.55 : AISLE_H - SHELF_DEPTH - 0.55;
    const sx = ox + 1.6 + r() * 0.8;
    const spillY = side < 0 ? AISLE_H - SHELF_DEPTH - 0.9 : SHELF_DEPTH + 0.1;
    obstacles.push({ x: sx, y: spillY, w: 0.8, h: 0.8, kind: "spill" });
    path.push({ x: ox - 1.2, y: detourY }, { x: ox + 1.2, y: detourY });
  }
  path.push(pregrasp);
  return { side, item: { x: itemX, y: shelfY, color: ITEM_COLORS[Math.floor(r() * ITEM_COLORS.length)] }, obstacles, products, start, pregrasp, reachExtension, path };
}

export function gripperPos(rb: RobotState, side: number): { x: number; y: number } {
  return { x: rb.x + 0.15, y: rb.y + side * (BASE_H / 2 + rb.arm) };
}

export function pathLength(p: { x: number; y: number }[]): number {
  let L = 0;
  for (let i = 1; i < p.length; i++) L += Math.hypot(p[i].x - p[i - 1].x, p[i].y - p[i - 1].y);
  return L;
}

export function pointAlong(p: { x: number; y: number }[], s: number): { x: number; y: number; heading: number } {
  for (let i = 1; i < p.length; i++) {
    const d = Math.hypot(p[i].x - p[i - 1].x, p[i].y - p[i - 1].y);
    const heading = Math.atan2(p[i].y - p[i - 1].y, p[i].x - p[i - 1].x);
    if (s <= d || i === p.length - 1) {
      const f = d > 0 ? Math.min(1, s / d) : 1;
      return { x: p[i - 1].x + f * (p[i].x - p[i - 1].x), y: p[i - 1].y + f * (p[i].y - p[i - 1].y), heading };
    }
    s -= d;
  }
  return { ...p[p.length - 1], heading: 0 };
}

/** Keep the robot base in the aisle and out of obstacles (teleoperation never fails, it is
 * blocked); what it ran into ("aisle end", "shelf" or the obstacle's kind), or null. */
export function clampRobot(rb: RobotState, layout: Layout): string | null {
  // the footprint's extent along x and y at the base's heading
  const c = Math.abs(Math.cos(rb.heading)), s = Math.abs(Math.sin(rb.heading));
  const hx = (c * BASE_W + s * BASE_H) / 2, hy = (s * BASE_W + c * BASE_H) / 2;
  let hit: string | null = null;
  const x = Math.min(AISLE_W - hx - 0.05, Math.max(hx + 0.05, rb.x));
  const y = Math.min(AISLE_H - SHELF_DEPTH - hy - 0.05, Math.max(SHELF_DEPTH + hy + 0.05, rb.y));
  if (x !== rb.x) hit = "aisle end";
  if (y !== rb.y) hit = "shelf";
  rb.x = x;
  rb.y = y;
  for (const o of layout.obstacles) {
    const dx = rb.x - (o.x + o.w / 2), dy = rb.y - (o.y + o.h / 2);
    const px = hx + o.w / 2 - Math.abs(dx), py = hy + o.h / 2 - Math.abs(dy);
    if (px > 0 && py > 0) {
      hit = o.kind;
      if (px < py) rb.x += Math.sign(dx || 1) * px;
      else rb.y += Math.sign(dy || 1) * py;
    }
  }
  return hit;
}

// --------------------------------------------------------------------------- drawing

export interface View {
  layout: Layout;
  robot: RobotState;
  item: ItemState;
  showPath: boolean;
  flash: number; // 0..1 red flash after a failure
  highlight: boolean;
  time: number;
  bubble?: string; // a speech bubble over the robot
  impact?: { x: number; y: number; t: number }; // a collision burst
  picks?: PickToken[]; // a block whose policy picks the items: the items left, the next one marked
}

// --------------------------------------------------------------------------- the items left

/** What the server sends with a trial of a block whose policy picks the items: the items that
 * remain per complexity and, when the robot sees only the front of a queue, the visible ones. */
export interface ScheduleItems { remaining: Record<string, number>; visible: Record<string, number> | null; }

/** One item still to collect: its complexity, whether the robot sees it, whether it goes for it now. */
export interface PickToken { complexity: string; visible: boolean; next: boolean; }

/** The items left, in the order of `complexities` (easiest first), visible ones before hidden
 * ones within a complexity, and the first visible item of the chosen complexity marked `next`. */
export function pickTokens(items: ScheduleItems, chosen: string, complexities: string[]): PickToken[] {
  const out: PickToken[] = [];
  const names = [...complexities, ...Object.keys(items.remaining).filter((c) => !complexities.includes(c))];
  for (const c of names) {
    const left = items.remaining[c] ?? 0;
    const seen = items.visible === null ? left : Math.min(left, items.visible[c] ?? 0);
    for (let k = 0; k < left; k++) out.push({ complexity: c, visible: k < seen, next: c === chosen && k === 0 && seen > 0 });
  }
  return out;
}

/** The tray of items left, drawn in screen pixels at the top right of a canvas: low items as
 * discs, the others as diamonds, items the robot cannot see yet faded, the next item ringed
 * and named. */
export function drawPickTray(g: CanvasRenderingContext2D, tokens: PickToken[], scale: number, time: number) {
  if (tokens.length === 0) return;
  const r = 7 * scale, gap = 5 * scale, pad = 8 * scale;
  const perRow = Math.max(1, Math.min(tokens.length, 20));
  const rows = Math.ceil(tokens.length / perRow);
  const next = tokens.find((t) => t.next);
  const title = `Items left: ${tokens.length}` + (next ? `  ·  next: ${next.complexity}` : "");
  g.save();
  g.font = `${11 * scale}px system-ui, sans-serif`;
  const w = pad * 2 + Math.max(perRow * (2 * r + gap) - gap, g.measureText(title).width);
  const h = pad * 2 + 16 * scale + rows * (2 * r + gap) - gap;
  const x0 = g.canvas.width - w - pad, y0 = pad;
  g.fillStyle = "rgba(29,35,48,0.85)";
  roundRect(g, x0, y0, w, h, 6 * scale);
  g.fill();
  g.fillStyle = "#f4f6f8";
  g.textBaseline = "top";
  g.fillText(title, x0 + pad, y0 + pad);
  tokens.forEach((t, i) => {
    const cx = x0 + pad + r + (i % perRow) * (2 * r + gap);
    const cy = y0 + pad + 16 * scale + r + Math.floor(i / perRow) * (2 * r + gap);
    g.globalAlpha = t.visible ? 1 : 0.3;
    g.fillStyle = t.complexity === "low" ? "#00c2a8" : "#ff7b00";
    g.beginPath();
    if (t.complexity === "low") g.arc(cx, cy, r * 0.8, 0, Math.PI * 2);
    else { g.moveTo(cx, cy - r); g.lineTo(cx + r, cy); g.lineTo(cx, cy + r); g.lineTo(cx - r, cy); g.closePath(); }
    g.fill();
    g.globalAlpha = 1;
    if (t.next) {
      g.strokeStyle = "rgba(255,45,111,0.95)";
      g.lineWidth = 2 * scale;
      g.beginPath();
      g.arc(cx, cy, r * (1.25 + 0.1 * Math.sin(time * 5)), 0, Math.PI * 2);
      g.stroke();
    }
  });
  g.restore();
}

function roundRect(g: CanvasRenderingContext2D, x: number, y: number, w: number, h: number, r: number) {
  g.beginPath();
  g.moveTo(x + r, y);
  g.arcTo(x + w, y, x + w, y + h, r);
  g.arcTo(x + w, y + h, x, y + h, r);
  g.arcTo(x, y + h, x, y, r);
  g.arcTo(x, y, x + w, y, r);
  g.closePath();
}

/** Draw the aisle in world units; the caller sets the transform. */
export function drawAisle(g: CanvasRenderingContext2D, v: View, px: number) {
  const { layout, robot, item } = v;
  // floor
  g.fillStyle = "#e9e4da";
  g.fillRect(0, 0, AISLE_W, AISLE_H);
  g.strokeStyle = "rgba(0,0,0,0.05)";
  g.lineWidth = 1 / px;
  for (let x = 0; x <= AISLE_W; x += 0.5) { g.beginPath(); g.moveTo(x, 0); g.lineTo(x, AISLE_H); g.stroke(); }
  for (let y = 0; y <= AISLE_H; y += 0.5) { g.beginPath(); g.moveTo(0, y); g.lineTo(AISLE_W, y); g.stroke(); }
  // shelves
  for (const s of [-1, 1]) {
    const y0 = s < 0 ? 0 : AISLE_H - SHELF_DEPTH;
    g.fillStyle = "#8a6a4f";
    g.fillRect(0, y0, AISLE_W, SHELF_DEPTH);
    g.fillStyle = "#a5825f";
    g.fillRect(0, s < 0 ? SHELF_DEPTH - 0.12 : y0, AISLE_W, 0.12);
    g.fillStyle = "rgba(0,0,0,0.18)";
    for (let x = 0; x <= AISLE_W; x += 2) g.fillRect(x - 0.03, y0, 0.06, SHELF_DEPTH);
  }
  for (const p of layout.products) {
    g.fillStyle = p.color;
    roundRect(g, p.x, p.y, p.w, p.h, 0.04);
    g.fill();
    g.fillStyle = "rgba(255,255,255,0.35)";
    g.fillRect(p.x + 0.04, p.y + 0.04, p.w * 0.35, Math.min(0.08, p.h / 4));
  }
  // obstacles
  for (const o of layout.obstacles) drawObstacle(g, o, px);
  // planned path
  if (v.showPath && layout.path.length > 1) {
    g.save();
    g.setLineDash([0.15, 0.12]);
    g.strokeStyle = "rgba(40,90,200,0.55)";
    g.lineWidth = 0.05;
    g.beginPath();
    g.moveTo(layout.path[0].x, layout.path[0].y);
    for (const p of layout.path.slice(1)) g.lineTo(p.x, p.y);
    g.stroke();
    g.restore();
  }
  // the misplaced item (when not yet in the bin and not held)
  if (item.visible && !item.inBin && !robot.holding) drawItem(g, item.x, item.y, layout.item.color, v.highlight, v.time);
  drawRobot(g, v);
  if (robot.holding && item.visible) drawItem(g, item.x, item.y, layout.item.color, false, v.time);
  if (v.bubble) drawBubble(g, robot.x, robot.y - BASE_H / 2 - 0.15, v.bubble);
  if (v.impact) drawImpact(g, v.impact.x, v.impact.y, v.impact.t);
  if (v.flash > 0) {
    g.fillStyle = `rgba(220,30,30,${0.35 * v.flash})`;
    g.fillRect(0, 0, AISLE_W, AISLE_H);
  }
}

function drawObstacle(g: CanvasRenderingContext2D, o: Box, px: number) {
  if (o.kind === "spill") {
    g.fillStyle = "rgba(90,160,220,0.55)";
    g.beginPath();
    g.ellipse(o.x + o.w / 2, o.y + o.h / 2, o.w / 2, o.h / 2.4, 0.3, 0, Math.PI * 2);
    g.fill();
    // wet floor cone
    g.fillStyle = "#ffcc00";
    g.beginPath();
    g.moveTo(o.x + o.w * 0.8, o.y + 0.1);
    g.lineTo(o.x + o.w * 0.95, o.y + 0.4);
    g.lineTo(o.x + o.w * 0.65, o.y + 0.4);
    g.closePath();
    g.fill();
    return;
  }
  g.fillStyle = o.kind === "crate" ? "#b0793f" : "#7d8590";
  roundRect(g, o.x, o.y, o.w, o.h, 0.05);
  g.fill();
  g.strokeStyle = "rgba(0,0,0,0.35)";
  g.lineWidth = 2 / px;
  g.stroke();
  // hazard stripes
  g.save();
  roundRect(g, o.x, o.y, o.w, o.h, 0.05);
  g.clip();
  g.strokeStyle = "rgba(255,210,0,0.85)";
  g.lineWidth = 0.09;
  for (let k = -2; k < 6; k++) {
    g.beginPath();
    g.moveTo(o.x + k * 0.3, o.y);
    g.lineTo(o.x + k * 0.3 + o.h, o.y + o.h);
    g.stroke();
  }
  g.restore();
  g.fillStyle = "rgba(0,0,0,0.55)";
  g.font = `${0.22}px sans-serif`;
  g.textAlign = "center";
  g.fillText(o.kind === "crate" ? "CRATE" : "CART", o.x + o.w / 2, o.y + o.h / 2 + 0.08);
}

function drawImpact(g: CanvasRenderingContext2D, x: number, y: number, t: number) {
  const r = 0.25 + 0.35 * Math.min(1, t * 3);
  g.save();
  g.globalAlpha = Math.max(0, 1 - t / 1.5);
  g.fillStyle = "#ffdd33";
  g.strokeStyle = "#e5484d";
  g.lineWidth = 0.05;
  g.beginPath();
  for (let i = 0; i < 16; i++) {
    const a = (i / 16) * Math.PI * 2;
    const rr = i % 2 ? r * 0.45 : r;
    g.lineTo(x + Math.cos(a) * rr, y + Math.sin(a) * rr);
  }
  g.closePath();
  g.fill();
  g.stroke();
  g.restore();
}

function drawBubble(g: CanvasRenderingContext2D, x: number, y: number, text: string) {
  g.font = "bold 0.26px system-ui, sans-serif";
  const w = g.measureText(text).width + 0.36;
  const h = 0.46;
  const bx = Math.max(0.1, Math.min(AISLE_W - w - 0.1, x - w / 2));
  const by = Math.max(0.1, y - h - 0.18);
  g.fillStyle = "#f5a524";
  roundRect(g, bx, by, w, h, 0.12);
  g.fill();
  g.beginPath();
  g.moveTo(x - 0.12, by + h);
  g.lineTo(x, by + h + 0.18);
  g.lineTo(x + 0.12, by + h);
  g.fill();
  g.fillStyle = "#1d2330";
  g.textAlign = "center";
  g.textBaseline = "middle";
  g.fillText(text, bx + w / 2, by + h / 2 + 0.01);
  g.textBaseline = "alphabetic";
}

function drawItem(g: CanvasRenderingContext2D, x: number, y: number, color: string, highlight: boolean, t: number) {
  if (highlight) {
    const r = 0.34 + 0.06 * Math.sin(t * 5);
    g.strokeStyle = "rgba(255,45,111,0.9)";
    g.lineWidth = 0.05;
    g.beginPath();
    g.arc(x, y, r, 0, Math.PI * 2);
    g.stroke();
  }
  g.fillStyle = color;
  g.beginPath();
  g.arc(x, y, 0.17, 0, Math.PI * 2);
  g.fill();
  g.fillStyle = "rgba(255,255,255,0.7)";
  g.beginPath();
  g.arc(x - 0.05, y - 0.05, 0.05, 0, Math.PI * 2);
  g.fill();
}

function drawRobot(g: CanvasRenderingContext2D, v: View) {
  const { robot, layout } = v;
  const shake = robot.shake > 0 ? Math.sin(v.time * 60) * 0.05 * robot.shake : 0;
  const rx = robot.x + shake, ry = robot.y;
  g.save();
  g.translate(rx, ry);
  // shadow
  g.fillStyle = "rgba(0,0,0,0.15)";
  roundRect(g, -BASE_W / 2 + 0.05, -BASE_H / 2 + 0.07, BASE_W, BASE_H, 0.12);
  g.fill();
  // wheels
  g.fillStyle = "#222";
  for (const [wx, wy] of [[-0.3, -0.38], [0.3, -0.38], [-0.3, 0.38], [0.3, 0.38]]) g.fillRect(wx - 0.11, wy - 0.05, 0.22, 0.1);
  // base
  g.fillStyle = "#f4f6f8";
  roundRect(g, -BASE_W / 2, -BASE_H / 2, BASE_W, BASE_H, 0.12);
  g.fill();
  g.strokeStyle = "#3a4250";
  g.lineWidth = 0.03;
  g.stroke();
  // heading marker
  g.fillStyle = "#2f6fde";
  g.beginPath();
  const hx = Math.cos(robot.heading) * 0.32, hy = Math.sin(robot.heading) * 0.22;
  g.arc(hx, hy, 0.06, 0, Math.PI * 2);
  g.fill();
  // bin at the back
  g.fillStyle = "#2f6fde";
  roundRect(g, -BASE_W / 2 + 0.06, -0.22, 0.34, 0.44, 0.04);
  g.fill();
  g.fillStyle = "#1c4aa0";
  g.fillRect(-BASE_W / 2 + 0.1, -0.18, 0.26, 0.36);
  for (let k = 0; k < Math.min(robot.binCount, 6); k++) {
    g.fillStyle = ITEM_COLORS[k % ITEM_COLORS.length];
    g.beginPath();
    g.arc(-BASE_W / 2 + 0.17 + (k % 2) * 0.12, -0.12 + Math.floor(k / 2) * 0.12, 0.05, 0, Math.PI * 2);
    g.fill();
  }
  g.restore();
  // arm: shoulder on the base, towards the item's shelf
  const side = layout.side;
  const sx = rx + 0.15, sy = ry;
  const gp = { x: rx + 0.15, y: ry + side * (BASE_H / 2 + robot.arm) };
  g.strokeStyle = "#5b6577";
  g.lineWidth = 0.1;
  g.lineCap = "round";
  g.beginPath();
  g.moveTo(sx, sy);
  g.lineTo(gp.x, gp.y);
  g.stroke();
  g.fillStyle = "#3a4250";
  g.beginPath();
  g.arc(sx, sy, 0.1, 0, Math.PI * 2);
  g.fill();
  // gripper jaws
  const open = 0.07 + 0.1 * robot.jaw;
  g.strokeStyle = "#ff9f1c";
  g.lineWidth = 0.05;
  for (const d of [-1, 1]) {
    g.beginPath();
    g.moveTo(gp.x + d * open, gp.y - side * 0.02);
    g.lineTo(gp.x + d * open, gp.y + side * 0.18);
    g.stroke();
  }
  g.beginPath();
  g.moveTo(gp.x - open, gp.y - side * 0.02);
  g.lineTo(gp.x + open, gp.y - side * 0.02);
  g.stroke();
}

export function drawWorld(c: HTMLCanvasElement, v: View) {
  const g = c.getContext("2d")!;
  const px = Math.min(c.width / AISLE_W, c.height / AISLE_H);
  g.setTransform(1, 0, 0, 1, 0, 0);
  g.fillStyle = "#1d2330";
  g.fillRect(0, 0, c.width, c.height);
  g.setTransform(px, 0, 0, px, (c.width - AISLE_W * px) / 2, (c.height - AISLE_H * px) / 2);
  drawAisle(g, v, px);
  if (v.picks) {
    g.setTransform(1, 0, 0, 1, 0, 0);
    drawPickTray(g, v.picks, Math.max(0.75, Math.min(2, c.width / 900)), v.time);
  }
}

export function drawLocal(c: HTMLCanvasElement, v: View) {
  const g = c.getContext("2d")!;
  const px = c.height / 2.6;
  g.setTransform(1, 0, 0, 1, 0, 0);
  g.fillStyle = "#1d2330";
  g.fillRect(0, 0, c.width, c.height);
  g.setTransform(px, 0, 0, px, c.width / 2 - v.robot.x * px, c.height / 2 - v.robot.y * px);
  drawAisle(g, v, px);
  // reach circle around the gripper
  const gp = gripperPos(v.robot, v.layout.side);
  g.strokeStyle = "rgba(255,159,28,0.6)";
  g.lineWidth = 0.02;
  g.setLineDash([0.06, 0.05]);
  g.beginPath();
  g.arc(gp.x, gp.y, REACH, 0, Math.PI * 2);
  g.stroke();
  g.setLineDash([]);
  g.setTransform(1, 0, 0, 1, 0, 0);
  vignette(g, c);
}

/** The camera on the gripper looking at the shelf: products from the front, the item growing
 * as the gripper gets closer, the jaws at the bottom of the frame. */
export function drawEndEffector(c: HTMLCanvasElement, v: View) {
  const g = c.getContext("2d")!;
  const W = c.width, H = c.height;
  const { layout, robot, item } = v;
  const gp = gripperPos(robot, layout.side);
  const shelfFront = layout.side < 0 ? SHELF_DEPTH : AISLE_H - SHELF_DEPTH;
  const depth = Math.max(0.05, Math.abs(gp.y - shelfFront) + 0.35); // distance to the shelf plane
  const f = 95; // focal length in px per unit at depth 1
  g.setTransform(1, 0, 0, 1, 0, 0);
  const grad = g.createLinearGradient(0, 0, 0, H);
  grad.addColorStop(0, "#3b3f47");
  grad.addColorStop(1, "#23262c");
  g.fillStyle = grad;
  g.fillRect(0, 0, W, H);
  const toX = (wx: number) => W / 2 + ((wx - gp.x) * f) / depth;
  const scale = f / depth;
  // shelf boards
  g.fillStyle = "#8a6a4f";
  for (const level of [0.25, 0.62, 0.98]) {
    const y = H * level;
    g.fillRect(0, y, W, Math.max(4, 0.08 * scale));
  }
  // products on the item's shelf, seen from the front
  for (const p of layout.products) {
    if (p.side !== layout.side) continue;
    const x0 = toX(p.x), x1 = toX(p.x + p.w);
    if (x1 < -20 || x0 > W + 20) continue;
    const h = p.h * scale * 0.9;
    g.fillStyle = p.color;
    g.fillRect(x0, H * 0.62 - h, x1 - x0 - 2, h);
    g.fillStyle = "rgba(255,255,255,0.25)";
    g.fillRect(x0 + 3, H * 0.62 - h + 3, (x1 - x0) * 0.3, 4);
  }
  if (item.visible && !item.inBin) {
    // held: in the jaws; fallen: on the floor at the bottom of the picture; else on its shelf
    const ix = robot.holding ? W / 2 : toX(item.x);
    const r = robot.holding ? 46 : 0.17 * scale;
    const iy = robot.holding ? H * 0.55 : item.fallen ? H - r * 0.8 : H * 0.62 - r;
    g.fillStyle = layout.item.color;
    g.beginPath();
    g.ellipse(ix, iy, r * 0.8, r, 0, 0, Math.PI * 2);
    g.fill();
    g.fillStyle = "rgba(255,255,255,0.6)";
    g.fillRect(ix - r * 0.8, iy - r * 0.2, r * 1.6, r * 0.3);
  }
  // crosshair
  g.strokeStyle = "rgba(120,255,160,0.7)";
  g.lineWidth = 1.5;
  g.beginPath();
  g.moveTo(W / 2 - 14, H / 2); g.lineTo(W / 2 + 14, H / 2);
  g.moveTo(W / 2, H / 2 - 14); g.lineTo(W / 2, H / 2 + 14);
  g.stroke();
  // jaws
  const open = 40 + 50 * robot.jaw;
  g.fillStyle = "#ff9f1c";
  g.fillRect(W / 2 - open - 18, H - 70, 18, 70);
  g.fillRect(W / 2 + open, H - 70, 18, 70);
  g.fillStyle = "#5b6577";
  g.fillRect(W / 2 - open - 18, H - 16, 2 * open + 36, 16);
  // distance readout
  const d = Math.hypot(gp.x - item.x, gp.y - item.y);
  g.fillStyle = d < REACH ? "#7dff9a" : "#d5d9e0";
  g.font = "13px system-ui, sans-serif";
  g.textAlign = "right";
  g.fillText(`distance to item ${d.toFixed(2)} m`, W - 10, 22);
  vignette(g, c);
}

function vignette(g: CanvasRenderingContext2D, c: HTMLCanvasElement) {
  const r = g.createRadialGradient(c.width / 2, c.height / 2, c.height * 0.35, c.width / 2, c.height / 2, c.width * 0.75);
  r.addColorStop(0, "rgba(0,0,0,0)");
  r.addColorStop(1, "rgba(0,0,0,0.35)");
  g.fillStyle = r;
  g.fillRect(0, 0, c.width, c.height);
}
