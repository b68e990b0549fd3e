// The participant page's trial: its start (or resumption after a reload), the robot's approach
// and reach, the participant's intervention or teleoperation, the trial sent to the server, the
// outcome's animation and banner; the page's clock (`tick`), which `?manual=1` hands to the tests
// (window.__scene.step).

import { ApiError, Current, uiEvent } from "../api";
import { poll } from "../input";
import { Outcome2D } from "../outcome2d";
import { Cause, makeLayout, pathLength, pointAlong } from "../scene";
import { chooseScene } from "../scene3d/page";
import { $, Saved, api, contacts, fmtReward, forget, freshItem, freshRobot, log, page, query, save, savedFor, setHint } from "./state";
import { draw, renderStatus, setPhase, showFatal } from "./status";
import { resetTeleop, teleop } from "./teleop";

export function startTrial(cur: Current) {
  page.current = cur;
  page.trialEvents = [];
  page.outcome = null;
  page.intervened = false;
  page.pending = null;
  const saved = savedFor(cur.trial);
  page.submissionId = saved?.submissionId ?? `${api.sessionId}-${cur.trial}-${Math.random().toString(36).slice(2, 10)}`;
  page.layout = makeLayout(cur.scene_seed, cur.complexity === "high");
  $("banner").className = "cut"; // the last trial's banner is gone before this trial starts
  const bin = page.robot.binCount;
  page.robot = freshRobot(page.layout);
  page.robot.binCount = bin;
  page.item = freshItem(page.layout);
  page.impact = undefined;
  page.anim2d = null;
  page.pathS = 0;
  page.pathL = approachLength(cur.scene_seed);
  if (saved) return resumeTrial(cur, saved);
  log("trial_start", { complexity: cur.complexity, robot_action: cur.robot_action, block: cur.block });
  if (cur.robot_action === "ask") {
    page.teleopStart = performance.now();
    resetTeleop();
    log("teleop_start", { reason: "asked" });
    setPhase("teleop");
    const why = cur.practice ? "Practice: the robot asks for your help, as it will in the study." : "The robot asks for your help:";
    setHint(`${why} Drive it to the item, grasp it and put it in the bin.`, 5);
  } else {
    setPhase("approach");
  }
}

/** The page was reloaded during this trial: carry on from what was kept, with its events. */
function resumeTrial(cur: Current, saved: Saved) {
  page.trialEvents = saved.events;
  page.intervened = saved.intervened;
  log("resumed", { phase: saved.phase });
  if (saved.pending) {
    // the trial had ended and was being saved: send it again (the same submission id)
    page.teleopStart = performance.now() - (saved.teleopMs ?? 0);
    Object.assign(page.robot, saved.robot);
    Object.assign(page.item, saved.item);
    sendTrial(saved.pending.human, saved.pending.effort);
    return;
  }
  if (saved.phase === "teleop" || saved.intervened) {
    Object.assign(page.robot, saved.robot, { shake: 0 });
    Object.assign(page.item, saved.item);
    page.driven = saved.driven;
    page.armTravel = saved.armTravel;
    page.graspAttempts = saved.graspAttempts;
    contacts.reset(saved.contacts ?? 0);
    page.inputs = saved.inputs ?? 0;
    page.teleopStart = performance.now() - (saved.teleopMs ?? 0);
    setPhase("teleop");
    setHint(cur.robot_action === "ask" ? "Welcome back: carry on helping the robot." : "Welcome back: you are still in control.", 4);
    return;
  }
  setPhase("approach"); // the robot had not finished its approach: it starts it again
}

export function intervene(via: string) {
  if (page.phase !== "approach" && page.phase !== "reach") return;
  page.intervened = true;
  log("intervene", { via, progress: page.pathS / page.pathL, arm: page.robot.arm });
  page.teleopStart = performance.now();
  resetTeleop();
  log("teleop_start", { reason: "intervened" });
  setPhase("teleop");
  setHint("You took over: drive to the item, grasp it (G) and deposit it in the bin (B).", 4);
}

function submit(human: "intervene" | "rely") {
  sendTrial(human, human === "intervene" ? performance.now() - page.teleopStart : null);
}

async function sendTrial(human: "intervene" | "rely", effort: number | null) {
  const cur = page.current!;
  page.pending = { human, effort };
  setPhase(human === "rely" ? "waiting" : "result");
  save(); // a reload from here on sends the same trial again
  try {
    // retried until the server answers; the submission id makes a repeat harmless
    const res = await api.submitTrial({ trial: cur.trial, submission_id: page.submissionId, human_action: human, effort_ms: effort, events: page.trialEvents });
    page.outcome = res.trial;
    page.st = res.state;
  } catch (e) {
    if (e instanceof ApiError && e.status === 409) {
      // the server is ahead of this page (another tab, or an earlier save): follow it
      forget();
      page.st = await api.state().catch(() => page.st);
      return page.route();
    }
    showFatal("Your trial could not be saved", `${(e as Error).message}. Please reload the page; what you did so far is kept.`);
    return;
  }
  page.pending = null;
  forget();
  if (human === "rely") setPhase("outcome");
  else {
    page.phaseT = 0;
    showBanner();
  }
  renderStatus();
}

function showBanner() {
  const o = page.outcome!;
  const r = fmtReward(o.reward);
  const text: Record<string, string> = {
    success: "Collected autonomously",
    collision: "Failure: the robot collided with its surroundings",
    dropped: "Failure: the robot dropped the item",
    teleoperated: o.robot_action === "ask" ? "Collected with your help" : "You took over and collected the item",
  };
  // a failure's text names the cause the animation showed (it fits the trial's complexity)
  const g = shownCause();
  if (g.cause === "strike") text[o.outcome] = `Failure: the robot struck the ${g.struck} and the item fell`;
  else if (g.cause === "slip") text[o.outcome] = "Failure: the item slipped out of the gripper and fell";
  const b = $("banner");
  b.innerHTML = `<span class="pts ${o.reward > 0 ? "pos" : o.reward < 0 ? "neg" : ""}">${r}</span> ${text[o.outcome] ?? o.outcome}${o.practice ? " (practice: not scored)" : ""}`;
  b.className = "show";
  page.shownScore = page.st.score;
  api.events([uiEvent("outcome_shown", { outcome: o.outcome, reward: o.reward, cause: g.cause }, o.trial)]).catch(() => undefined);
}

/** The cause of a failure the outcome's animation showed (3-D or 2-D), and what was struck. */
export function shownCause(): { cause: Cause | null; struck: string | null } {
  const g = page.scene3d ? page.scene3d.state() : page.anim2d;
  return { cause: g?.cause ?? null, struck: g?.struck ?? null };
}

function afterResult() {
  $("banner").className = "cut";
  page.route();
}
// --------------------------------------------------------------------------- per frame

let last = performance.now();
export function frame(now: number) {
  const dt = Math.min(0.1, (now - last) / 1000); // a slow frame (software WebGL) still keeps time
  last = now;
  if (!page.manual) {
    tick(dt);
    draw();
    renderStatus();
  }
  requestAnimationFrame(frame);
}

/** The page's state `dt` seconds on (the clock of the animations and of the teleoperation). */
function tick(dt: number) {
  page.clock += dt;
  const cmd = poll();
  const k = dt * page.speed;
  page.phaseT += k;
  page.flash = Math.max(0, page.flash - dt * 1.5);
  page.robot.shake = Math.max(0, page.robot.shake - dt * 2);

  if (page.phase === "approach" || page.phase === "reach") {
    if (cmd.intervene) intervene(cmd.interveneVia ?? "key");
  }
  if (page.phase === "approach") {
    page.pathS = Math.min(page.pathL, page.pathS + 1.7 * k);
    const p = approachPose(page.pathS);
    page.robot.x = p.x;
    page.robot.y = p.y;
    page.robot.heading = p.heading;
    if (page.pathS >= page.pathL) {
      setPhase("reach");
      page.robot.heading = 0;
    }
  } else if (page.phase === "reach") {
    page.robot.jaw = Math.min(1, page.robot.jaw + 2 * k);
    page.robot.arm = Math.min(page.layout.reachExtension, page.robot.arm + 1.1 * k);
    if (page.robot.arm >= page.layout.reachExtension) {
      log("grasp", { by: "robot" });
      submit("rely");
    }
  } else if (page.phase === "outcome") {
    if (!page.scene3d) {
      page.anim2d ??= new Outcome2D(page.outcome!.outcome, page.layout, page.robot);
      if (page.anim2d.step(page.phaseT, k, page.robot, page.item)) toResult();
      page.impact = page.anim2d.impact;
    } else if (page.scene3d.outcome(page.outcome!.outcome, page.phaseT, k, page.robot, page.item)) toResult();
  } else if (page.phase === "teleop") {
    if (teleop(cmd, k)) submit("intervene");
    if (page.clock - page.lastSave > 0.5) save();
  } else if (page.phase === "result") {
    if (page.outcome && page.phaseT > 1.6) afterResult();
  }
}

function toResult() {
  setPhase("result");
  showBanner();
}

// --------------------------------------------------------------------------- the 3-D scene (scene3d/)
// The views are drawn in 3-D where WebGL works and the study does not ask for the 2-D scene
// (`"scene": "2d"`, or `?scene=2d`); the session records which scene ran (a "scene" event).
// `?quality=0..4` fixes the 3-D detail; `?manual=1` stops the page's clock: the tests then move
// it with window.__scene.step(seconds, frames), never by the wall clock.

const APPROACH_V = 1.7; // the rate of pathS (m/s), as the 2-D scene drives

export function useScene(asked: string | undefined) {
  const c = chooseScene(query, asked, { world: $<HTMLCanvasElement>("world"), local: $<HTMLCanvasElement>("local"), ee: $<HTMLCanvasElement>("ee") });
  page.scene3d = c.scene;
  document.body.dataset.scene = c.ran;
  api.events([uiEvent("scene", { scene: c.ran, asked: c.asked, reason: c.reason })]).catch(() => undefined);
}

function approachLength(seed: number): number {
  if (!page.scene3d) return pathLength(page.layout.path);
  page.scene3d.setTrial(page.layout, seed, page.item);
  return page.scene3d.drive.duration * APPROACH_V;
}

function approachPose(s: number) {
  return page.scene3d ? page.scene3d.drivePose(s / APPROACH_V) : pointAlong(page.layout.path, s);
}

(window as unknown as { __scene: unknown }).__scene = {
  scene: () => (page.scene3d ? "3d" : "2d"),
  /** Stop (true) or restart (false) the page's own clock. */
  manual: (on: boolean) => {
    page.manual = on;
    last = performance.now();
  },
  /** Move the page's clock on by `frames` frames of `dt` seconds; draw the last one unless `render` is false. */
  step: (dt: number, frames = 1, render = true) => {
    for (let i = 0; i < frames; i++) tick(dt);
    if (render) draw();
    renderStatus();
    return page.scene3d?.state() ?? null;
  },
  state: () => page.scene3d?.state() ?? null,
};

