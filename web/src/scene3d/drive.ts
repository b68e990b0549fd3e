// The base's drive: a shortest path around the obstacles (a visibility graph over the corners
// of the obstacles grown by the base's half width), then a timed motion along it that turns on
// the spot at each corner and accelerates and brakes on each straight. Pure geometry.

import { AISLE_H, AISLE_W, BASE_H, BASE_W, Layout, SHELF_DEPTH } from "../scene";
import { Pose, wrapAngle } from "./arm";

type P2 = { x: number; y: number };
// obstacles grown by the base's half width and a margin across the aisle, and by its turning
// radius along it (the base turns on the spot at their corners)
const GROW = BASE_H / 2 + 0.1;
const GROW_X = Math.hypot(BASE_W / 2, BASE_H / 2) + 0.05;
export const V_MAX = 1.6;      // m/s
export const A_MAX = 1.0;      // m/s²
export const W_MAX = 2.0;      // rad/s
export const ALPHA = 3.0;      // rad/s²

interface Rect { x0: number; y0: number; x1: number; y1: number; }

function grown(l: Layout): Rect[] {
  return l.obstacles.map((o) => ({ x0: o.x - GROW_X, y0: o.y - GROW, x1: o.x + o.w + GROW_X, y1: o.y + o.h + GROW }));
}

/** Whether the straight move from a to b stays clear of the grown rectangles (sampled every 2 cm). */
function clear(a: P2, b: P2, rects: Rect[]): boolean {
  const n = Math.max(2, Math.ceil(Math.hypot(b.x - a.x, b.y - a.y) / 0.02));
  for (let i = 0; i <= n; i++) {
    const x = a.x + ((b.x - a.x) * i) / n, y = a.y + ((b.y - a.y) * i) / n;
    for (const r of rects) if (x > r.x0 + 1e-6 && x < r.x1 - 1e-6 && y > r.y0 + 1e-6 && y < r.y1 - 1e-6) return false;
  }
  return true;
}

/** The shortest path from the layout's start to its pregrasp point around the obstacles. */
export function planPath(l: Layout): P2[] {
  const rects = grown(l);
  const lo = SHELF_DEPTH + GROW, hi = AISLE_H - SHELF_DEPTH - GROW;
  const nodes: P2[] = [l.start, l.pregrasp];
  for (const r of rects) {
    for (const x of [r.x0, r.x1]) for (const y of [r.y0, r.y1]) if (y >= lo && y <= hi && x > 0 && x < AISLE_W) nodes.push({ x, y });
  }
  // Dijkstra over the visibility graph (a handful of nodes)
  const n = nodes.length;
  const dist = new Array(n).fill(Infinity);
  const prev = new Array(n).fill(-1);
  const done = new Array(n).fill(false);
  dist[0] = 0;
  for (;;) {
    let u = -1;
    for (let i = 0; i < n; i++) if (!done[i] && dist[i] < Infinity && (u < 0 || dist[i] < dist[u])) u = i;
    if (u < 0 || u === 1) break;
    done[u] = true;
    for (let v = 0; v < n; v++) {
      if (done[v] || !clear(nodes[u], nodes[v], rects)) continue;
      const d = dist[u] + Math.hypot(nodes[v].x - nodes[u].x, nodes[v].y - nodes[u].y);
      if (d < dist[v]) { dist[v] = d; prev[v] = u; }
    }
  }
  if (dist[1] === Infinity) return l.path; // cannot happen with the layouts of makeLayout
  const path: P2[] = [];
  for (let v = 1; v >= 0; v = prev[v]) path.unshift(nodes[v]);
  return path;
}

/** A rest-to-rest move of length d: its duration and the distance covered at time t. */
function profile(d: number, vmax: number, amax: number): { T: number; at: (t: number) => number } {
  const ta = vmax / amax;
  if (d <= vmax * ta) {
    const th = Math.sqrt(d / amax);
    return { T: 2 * th, at: (t) => (t < th ? 0.5 * amax * t * t : d - 0.5 * amax * Math.max(0, 2 * th - t) ** 2) };
  }
  const tc = d / vmax - ta;
  const T = 2 * ta + tc;
  return {
    T,
    at: (t) => (t < ta ? 0.5 * amax * t * t : t < ta + tc ? 0.5 * vmax * ta + vmax * (t - ta) : d - 0.5 * amax * Math.max(0, T - t) ** 2),
  };
}

interface Step { t0: number; T: number; pose: (t: number) => Pose; }

/** The timed drive along a path: a turn towards each leg, the leg, and a last turn to face
 * along the aisle (heading 0). */
export class Drive {
  readonly steps: Step[] = [];
  readonly duration: number;

  constructor(readonly path: P2[], heading0 = 0) {
    let t = 0, h = heading0;
    const turn = (p: P2, to: number) => {
      const dh = wrapAngle(to - h);
      if (Math.abs(dh) < 1e-6) return;
      const pr = profile(Math.abs(dh), W_MAX, ALPHA);
      const from = h;
      this.steps.push({ t0: t, T: pr.T, pose: (s) => ({ x: p.x, y: p.y, heading: from + Math.sign(dh) * pr.at(s) }) });
      t += pr.T;
      h = to;
    };
    for (let i = 1; i < path.length; i++) {
      const a = path[i - 1], b = path[i];
      const d = Math.hypot(b.x - a.x, b.y - a.y);
      if (d < 1e-6) continue;
      turn(a, Math.atan2(b.y - a.y, b.x - a.x));
      const pr = profile(d, V_MAX, A_MAX);
      const hh = h;
      this.steps.push({ t0: t, T: pr.T, pose: (s) => { const f = pr.at(s) / d; return { x: a.x + f * (b.x - a.x), y: a.y + f * (b.y - a.y), heading: hh }; } });
      t += pr.T;
    }
    turn(path[path.length - 1], 0);
    this.duration = t;
  }

  /** The base's pose at time t (s) after it set off. */
  at(t: number): Pose {
    const last = this.path[this.path.length - 1];
    if (this.steps.length === 0) return { ...last, heading: 0 };
    for (const s of this.steps) if (t < s.t0 + s.T) return s.pose(Math.max(0, t - s.t0));
    return { x: last.x, y: last.y, heading: 0 };
  }
}
