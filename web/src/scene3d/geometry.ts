// The aisle in three dimensions, derived from the 2-D layout of a trial (scene.ts makeLayout):
// shelf units with boards at four heights, the products on every board, the item on its board.
// Pure geometry (no three.js), so that it can be checked in node.
// Frame: x along the aisle, y across it (as in the 2-D layout), z up; metres.

import { AISLE_H, AISLE_W, Layout, SHELF_DEPTH, rng } from "../scene";

/** An axis-aligned box: its minimum and maximum corners. */
export interface Aabb { min: [number, number, number]; max: [number, number, number]; }

export interface Product3 extends Aabb { color: string; }

export interface Aisle3 {
  boards: Aabb[];    // shelf boards, side panels and the back of each unit
  products: Product3[];
  item: { x: number; y: number; z: number; level: number; radius: number; height: number };
  front: number;     // y of the front of the item's shelf
}

/** Heights of the tops of the boards (the lowest is the unit's plinth). */
export const LEVELS = [0.12, 0.52, 0.92, 1.32];
export const BOARD = 0.03;
export const UNIT_H = 1.75;
export const ITEM_R = 0.055;
export const ITEM_H = 0.16;
const PRODUCT_COLORS = ["#e4572e", "#f3a712", "#29335c", "#669bbc", "#a8c686", "#d1495b", "#edae49", "#00798c", "#8e7dbe", "#f7b2ad"];

function box(x0: number, y0: number, z0: number, x1: number, y1: number, z1: number): Aabb {
  return { min: [Math.min(x0, x1), Math.min(y0, y1), Math.min(z0, z1)], max: [Math.max(x0, x1), Math.max(y0, y1), Math.max(z0, z1)] };
}

/** The aisle of a trial: the same seed gives the same shelves, products and item. The 2-D
 * layout's random stream is left as it is (the 2-D scene stays the same); the heights come
 * from a stream of their own. */
export function makeAisle(layout: Layout, seed: number): Aisle3 {
  const r = rng((seed ^ 0x5bd1e995) >>> 0);
  const level = Math.floor(r() * LEVELS.length);
  const side = layout.side;
  const item = { x: layout.item.x, y: layout.item.y, z: LEVELS[level] + ITEM_H / 2, level, radius: ITEM_R, height: ITEM_H };
  const boards: Aabb[] = [];
  const products: Product3[] = [];
  for (const s of [-1, 1] as const) {
    const y0 = s < 0 ? 0 : AISLE_H - SHELF_DEPTH;
    const y1 = y0 + SHELF_DEPTH;
    const front = s < 0 ? y1 : y0;
    for (const h of LEVELS) boards.push(box(0, y0, h - BOARD, AISLE_W, y1, h));
    boards.push(box(0, s < 0 ? 0 : AISLE_H - 0.04, 0, AISLE_W, s < 0 ? 0.04 : AISLE_H, UNIT_H)); // the back
    // side panels between units, every 2 m, except where the item is taken out
    for (let x = 0; x <= AISLE_W + 1e-9; x += 2) {
      if (s === side && Math.abs(x - item.x) < 0.45) continue;
      boards.push(box(x - 0.02, y0, 0, x + 0.02, y1, UNIT_H));
    }
    for (let li = 0; li < LEVELS.length; li++) {
      const clear = (li + 1 < LEVELS.length ? LEVELS[li + 1] - BOARD : UNIT_H) - LEVELS[li];
      let x = 0.08;
      while (x < AISLE_W - 0.35) {
        const w = 0.12 + r() * 0.2;
        const d = 0.18 + r() * 0.2;
        const h = Math.min(clear - 0.06, 0.12 + r() * 0.2);
        const c = PRODUCT_COLORS[Math.floor(r() * PRODUCT_COLORS.length)];
        const near = Math.abs(x % 2) < 0.03 || Math.abs((x + w) % 2) < 0.03 || Math.floor(x / 2) !== Math.floor((x + w) / 2);
        const gap = s === side && li === level && x < item.x + 0.2 && x + w > item.x - 0.2;
        if (!near && !gap) {
          const fy = front + s * 0.02; // the products stand at the front of the board
          products.push({ ...box(x, fy, LEVELS[li], x + w, fy + s * d, LEVELS[li] + h), color: c });
        }
        x += w + 0.03 + r() * 0.06;
      }
    }
  }
  return { boards, products, item, front: side < 0 ? SHELF_DEPTH : AISLE_H - SHELF_DEPTH };
}

/** Squared distance from a point to a box (0 inside). */
export function distToBox2(p: readonly number[], b: Aabb): number {
  let d = 0;
  for (let i = 0; i < 3; i++) {
    const v = p[i] < b.min[i] ? b.min[i] - p[i] : p[i] > b.max[i] ? p[i] - b.max[i] : 0;
    d += v * v;
  }
  return d;
}

/** Whether the capsule from a to b of radius rad touches the box (sampled every 1 cm). */
export function capsuleHitsBox(a: readonly number[], b: readonly number[], rad: number, bx: Aabb): boolean {
  // apart when the capsule's bounding box misses the box grown by the radius
  for (let i = 0; i < 3; i++) if (Math.min(a[i], b[i]) - rad > bx.max[i] || Math.max(a[i], b[i]) + rad < bx.min[i]) return false;
  const n = Math.max(2, Math.ceil(Math.hypot(b[0] - a[0], b[1] - a[1], b[2] - a[2]) / 0.01));
  const r2 = rad * rad;
  for (let i = 0; i <= n; i++) {
    const t = i / n;
    const p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])];
    if (distToBox2(p, bx) < r2) return true;
  }
  return false;
}
