// What the participant page needs around the 3-D scene: which scene draws the views, and the
// contacts of a teleoperation (counted, pushed back).

import { Layout, RobotState, clampRobot } from "../scene";
import { Scene3D } from "./index";
import { ViewName, webglAvailable } from "./views";

export interface SceneChoice { scene: Scene3D | null; ran: "3d" | "2d"; asked: string; reason: string; }

/** The 3-D scene where WebGL works and neither the study (`asked`) nor the link (`?scene=2d`)
 * asks for the 2-D one; `?quality=0..4` fixes its detail. */
export function chooseScene(query: URLSearchParams, asked: string | undefined, canvases: Record<ViewName, HTMLCanvasElement>): SceneChoice {
  const want = query.get("scene") ?? asked ?? "3d";
  if (want === "2d") return { scene: null, ran: "2d", asked: want, reason: "asked" };
  if (!webglAvailable()) return { scene: null, ran: "2d", asked: want, reason: "no webgl" };
  try {
    const q = parseInt(query.get("quality") ?? "", 10);
    return { scene: new Scene3D(canvases, q >= 0 && q <= 4 ? q : null), ran: "3d", asked: want, reason: "webgl" };
  } catch (e) {
    return { scene: null, ran: "2d", asked: want, reason: `webgl failed: ${(e as Error).message}`.slice(0, 200) };
  }
}

/** The contacts of a teleoperation: one begins when the base or the arm strikes something it
 * was not touching half a second before; the base is then pushed 5 cm back from where it was
 * driven. */
export class Contacts {
  count = 0;
  private touching: string | null = null;
  private at = 0;

  reset(count = 0) {
    this.count = count;
    this.touching = null;
  }

  /** What was struck this frame (or null); true when a contact begins. */
  touch(hit: string | null, clock: number, robot: RobotState, layout: Layout, vx: number, vy: number): boolean {
    const begins = !!hit && hit !== this.touching;
    if (begins) {
      this.count++;
      const n = Math.hypot(vx, vy);
      if (!hit.startsWith("arm") && n > 0) {
        robot.x -= (0.05 * vx) / n;
        robot.y -= (0.05 * vy) / n;
        clampRobot(robot, layout);
      }
    }
    if (hit) this.at = clock;
    this.touching = hit ?? (clock - this.at > 0.5 ? null : this.touching);
    return begins;
  }
}
