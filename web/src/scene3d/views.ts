// One WebGL renderer draws the one scene graph through the three cameras of the paper's Fig. 1
// (world, local on the robot's head, end-effector in the gripper) and copies each picture into
// its canvas on the page. The detail (resolution, shadows, antialiasing) follows the measured
// frame time, or a fixed quality tier (`?quality=0..4`).

import * as THREE from "three";

export type ViewName = "world" | "local" | "ee";
export const VIEW_NAMES: ViewName[] = ["world", "local", "ee"];

/** The quality tiers, lowest first: resolution scale, shadows, antialiasing. */
export const TIERS = [
  { scale: 0.5, shadows: false, antialias: false },
  { scale: 0.75, shadows: false, antialias: false },
  { scale: 1, shadows: false, antialias: false },
  { scale: 1, shadows: true, antialias: false },
  { scale: 1, shadows: true, antialias: true },
];

/** Whether this browser can draw WebGL at all (checked on a throwaway canvas). */
export function webglAvailable(): boolean {
  try {
    const c = document.createElement("canvas");
    return !!(window.WebGLRenderingContext && (c.getContext("webgl2") || c.getContext("webgl")));
  } catch {
    return false;
  }
}

export class Views {
  renderer!: THREE.WebGLRenderer;
  readonly cameras: Record<ViewName, THREE.PerspectiveCamera> = {
    world: new THREE.PerspectiveCamera(30, 2.6, 0.1, 60),
    local: new THREE.PerspectiveCamera(62, 1.4, 0.05, 40),
    ee: new THREE.PerspectiveCamera(70, 1.4, 0.02, 30),
  };
  readonly calls: Record<ViewName, number> = { world: 0, local: 0, ee: 0 };
  tier: number;
  frameMs = 0;       // the mean time to draw the three views, over the last frames
  private samples: number[] = [];
  private lastChange = 0;
  private windowStart = 0;

  constructor(readonly scene: THREE.Scene, readonly sun: THREE.DirectionalLight, readonly fixedTier: number | null) {
    this.tier = fixedTier ?? 1;
    this.makeRenderer();
  }

  private makeRenderer() {
    const t = TIERS[this.tier];
    this.renderer?.dispose();
    this.renderer = new THREE.WebGLRenderer({ antialias: t.antialias, powerPreference: "high-performance", precision: "mediump" });
    this.renderer.info.autoReset = false;
    this.applyTier();
  }

  private applyTier() {
    const t = TIERS[this.tier];
    this.renderer.shadowMap.enabled = t.shadows;
    this.sun.castShadow = t.shadows;
    this.scene.traverse((o) => {
      const m = (o as THREE.Mesh).material as THREE.Material | undefined;
      if (m) m.needsUpdate = true;
    });
  }

  private setTier(tier: number) {
    const before = TIERS[this.tier];
    this.tier = tier;
    if (TIERS[tier].antialias !== before.antialias) this.makeRenderer();
    else this.applyTier();
  }

  /** Draw every view into its canvas; `overlay` draws on top (2-D) of each. */
  render(canvases: Record<ViewName, HTMLCanvasElement>, overlay: (name: ViewName, g: CanvasRenderingContext2D) => void) {
    const t0 = performance.now();
    const scale = TIERS[this.tier].scale * Math.min(2, window.devicePixelRatio || 1);
    const size: Record<string, [number, number]> = {};
    let W = 1, H = 1;
    for (const n of VIEW_NAMES) {
      const c = canvases[n];
      const w = Math.max(16, Math.round((c.clientWidth || c.width) * scale)), h = Math.max(16, Math.round((c.clientHeight || c.height) * scale));
      size[n] = [w, h];
      W = Math.max(W, w);
      H = Math.max(H, h);
    }
    const cv = this.renderer.domElement;
    if (cv.width !== W || cv.height !== H) this.renderer.setSize(W, H, false);
    for (const n of VIEW_NAMES) {
      const [w, h] = size[n];
      const c = canvases[n];
      if (c.width !== w || c.height !== h) {
        c.width = w;
        c.height = h;
      }
      const cam = this.cameras[n];
      if (cam.aspect !== w / h) {
        cam.aspect = w / h;
        cam.updateProjectionMatrix();
      }
      this.renderer.setViewport(0, 0, w, h);
      this.renderer.info.reset();
      this.renderer.render(this.scene, cam);
      this.calls[n] = this.renderer.info.render.calls;
      const g = c.getContext("2d");
      if (!g) continue;
      g.drawImage(cv, 0, H - h, w, h, 0, 0, w, h);
      overlay(n, g);
    }
    this.measure(performance.now() - t0);
  }

  private measure(ms: number) {
    const now = performance.now();
    this.samples.push(ms);
    if (now - this.windowStart < 1000 || this.samples.length < 3) return;
    this.frameMs = this.samples.reduce((a, b) => a + b, 0) / this.samples.length;
    this.samples = [];
    this.windowStart = now;
    if (this.fixedTier !== null) return;
    // down at once when a frame takes too long; up only after a calm while
    if (this.frameMs > 45 && this.tier > 0) this.setTier(this.tier - 1);
    else if (this.frameMs < 12 && this.tier < TIERS.length - 1 && now - this.lastChange > 4000) this.setTier(this.tier + 1);
    else return;
    this.lastChange = now;
  }

  /** Where a world point falls in each camera's picture (normalised device coordinates). */
  project(p: THREE.Vector3): Record<ViewName, { x: number; y: number; z: number; inFrame: boolean }> {
    const out = {} as Record<ViewName, { x: number; y: number; z: number; inFrame: boolean }>;
    for (const n of VIEW_NAMES) {
      const q = p.clone().project(this.cameras[n]);
      out[n] = { x: q.x, y: q.y, z: q.z, inFrame: Math.abs(q.x) <= 1 && Math.abs(q.y) <= 1 && q.z > -1 && q.z < 1 };
    }
    return out;
  }
}
