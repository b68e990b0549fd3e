// The participant page's screens and status panel: which screen shows, the views drawn (3-D or
// 2-D), the status panel (trial, score, mode, hint), and the state the browser tests read.

import { REACH, View, drawEndEffector, drawLocal, drawWorld, pickTokens } from "../scene";
import { gamepadName } from "../input";
import { $, Phase, contacts, page } from "./state";
import { gripper } from "./teleop";

export function setPhase(p: Phase) {
  page.phase = p;
  page.phaseT = 0;
  document.body.dataset.phase = p;
  for (const s of ["consent", "instructions", "quiz", "task", "done", "error"]) $(`screen-${s}`).hidden = true;
  if (p === "consent") $("screen-consent").hidden = false;
  else if (p === "instructions") $("screen-instructions").hidden = false;
  else if (p === "quiz") $("screen-quiz").hidden = false;
  else if (p === "done") $("screen-done").hidden = false;
  else if (p === "error") $("screen-error").hidden = false;
  else if (p !== "loading") $("screen-task").hidden = false;
  $("screen-report").hidden = p !== "report";
  $("screen-questionnaire").hidden = p !== "questionnaire";
  if (p === "report" || p === "questionnaire" || p === "done") page.hintUntil = 0;
  renderStatus();
}

/** A problem that stops the study on this page: a screen of its own, not a blank page. */
export function showFatal(title: string, msg: string) {
  $("error-title").textContent = title;
  $("error-text").textContent = msg;
  setPhase("error");
}

// --------------------------------------------------------------------------- drawing and status

function view(): View {
  const asking = page.phase === "teleop" && !page.intervened && !page.robot.holding && !page.item.inBin;
  return {
    layout: page.layout, robot: page.robot, item: page.item, showPath: page.phase === "approach", flash: page.flash, highlight: !page.robot.holding && !page.item.inBin && !page.item.fallen, time: page.clock, bubble: asking ? "Please help me!" : undefined, impact: page.impact, picks: picks(),
  };
}

/** The items left in a block whose policy picks them, the one of this trial marked (until it is in the bin). */
function picks() {
  const items = page.current?.items;
  if (!items) return undefined;
  const tokens = pickTokens(items, page.current!.complexity, ["low", "high"]);
  if (!page.item.inBin) return tokens;
  const i = tokens.findIndex((t) => t.next);
  return tokens.filter((_, k) => k !== i);
}

export function draw() {
  const v = view();
  if (page.scene3d) return page.scene3d.draw(v, page.phase);
  drawWorld($<HTMLCanvasElement>("world"), v);
  drawLocal($<HTMLCanvasElement>("local"), v);
  drawEndEffector($<HTMLCanvasElement>("ee"), v);
}

let lastStatus = "";
export function renderStatus() {
  if (!page.st) return;
  const trial = page.current ? page.current.trial : page.st.trials_done;
  let mode = "";
  let cls = "";
  if (page.phase === "approach" || page.phase === "reach" || page.phase === "waiting" || (page.phase === "outcome" && page.current?.robot_action === "autonomous")) {
    mode = "Collecting autonomously";
    cls = "auto";
  } else if (page.phase === "teleop") {
    mode = page.intervened ? "You are in control (intervention)" : "Asking for your help";
    cls = page.intervened ? "teleop" : "ask";
  } else if (page.phase === "result") {
    mode = "Trial complete";
    cls = "idle";
  } else if (page.phase === "report" || page.phase === "questionnaire") {
    mode = "Your rating, please";
    cls = "idle";
  }
  let h = page.clock < page.hintUntil ? page.hint : "";
  if (!h && page.phase === "teleop") h = teleopHint();
  if (!h && (page.phase === "approach" || page.phase === "reach")) h = "Watch the robot. Intervene (Space) if you think it will fail.";
  const pad = gamepadName();
  const key = [trial, page.st.trials_total, page.shownScore, mode, cls, h, pad, page.phase, page.current?.complexity].join("|");
  if (key === lastStatus) return;
  lastStatus = key;
  // practice trials are counted apart: the study's trials run 1..N as the end page counts them
  const np = page.st.practice_trials;
  const practice = page.current ? page.current.practice : trial <= np;
  $("trial-no").textContent = practice ? `${trial} / ${np}` : `${Math.max(0, trial - np)} / ${page.st.trials_total - np}`;
  $("score").textContent = String(page.shownScore);
  const m = $("mode");
  m.textContent = mode;
  m.className = `mode ${cls}`;
  $("hint").textContent = h;
  $("block-name").textContent = !page.current ? "" : page.current.practice ? "Practice trial (not scored)" : `Block ${page.current.block_position} of ${page.st.blocks.length}`;
  $("gamepad").textContent = pad ? `Gamepad: ${pad.slice(0, 40)}` : "No gamepad (keyboard works)";
  $<HTMLButtonElement>("intervene-btn").disabled = !(page.phase === "approach" || page.phase === "reach");
}

(window as unknown as { trustseek: unknown }).trustseek = {
  state: () => ({
    phase: page.phase, trial: page.current?.trial ?? null, robot_action: page.current?.robot_action ?? null, complexity: page.current?.complexity ?? null,
    robot: { x: page.robot.x, y: page.robot.y, heading: page.robot.heading, arm: page.robot.arm, holding: page.robot.holding, jaw: page.robot.jaw, closed: !!page.robot.closed, tool: page.robot.tool ?? null },
    item: { x: page.item.x, y: page.item.y, z: page.item.z, inBin: page.item.inBin, fallen: !!page.item.fallen },
    gripper: gripper(), reach: REACH, contacts: contacts.count,
    path: page.scene3d?.drive ? page.scene3d.drive.path : page.layout.path, obstacles: page.layout.obstacles, side: page.layout.side, score: page.st?.score ?? null, shown_score: page.shownScore,
    practice: page.current?.practice ?? null, picks: picks() ?? null, speed: page.speed, trial_label: $("trial-no").textContent, retries: page.retries, saving: page.pending !== null, connection: $("connection").hidden ? "ok" : "retrying",
  }),
};

/** What to do next in a teleoperation. */
function teleopHint(): string {
  const r = page.robot;
  if (r.holding) return r.arm > 0.3 ? "Bring the gripper back over the robot (K), then press B to deposit." : "Press B to deposit the item in the bin.";
  const g = gripper();
  const near = Math.hypot(g.x - page.item.x, g.y - page.item.y) <= REACH;
  if (near && r.closed) return "Open the gripper (G) and put it around the item.";
  if (near) return "Gripper at the item: when it is around the item, press G to close it.";
  return "Drive (\u2191\u2193, turn \u2190\u2192), move the gripper (I/K, J/L, R/F) to the item.";
}
