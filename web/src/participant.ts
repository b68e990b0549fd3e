// The participant's supervision interface (the paper's Fig. 1): world view, local view,
// end-effector view and status panel; consent, instructions, trials, self-reports.
//
// The server decides everything that matters (complexity, robot action, outcome, score);
// this page animates it, lets the participant intervene or teleoperate, and reports back.
// Only the study sets the pace (its animation_speed, recorded with the session); `?speed=4`
// multiplies every motion in a preview only, never on a participant's link.
// `?retry_cap=ms` caps the wait between retries while the server is unreachable (default 10 s);
// the page retries for as long as it stays open and keeps the trial in progress in
// localStorage, so that a reload resumes it where it was.

import { Api, ApiError, Connection, Current, Questionnaire, Quiz, State, TrialResult, UIEvent } from "./api";
import { gamepadName, installKeyboard, poll } from "./input";
import {
  AISLE_H, ARM_MAX, BASE_H, REACH, SHELF_DEPTH, ItemState, Layout, RobotState, View, clampRobot, drawEndEffector, drawLocal, drawWorld,
  gripperPos, makeLayout, pathLength, pickTokens, pointAlong,
} from "./scene";
import { Scene3D } from "./scene3d";
import { Contacts, chooseScene } from "./scene3d/page";

type Phase = "loading" | "consent" | "instructions" | "quiz" | "approach" | "reach" | "waiting" | "outcome" | "teleop" | "result" | "report" | "questionnaire" | "done" | "error";

const $ = <T extends HTMLElement = HTMLElement>(id: string) => document.getElementById(id) as T;
const token = decodeURIComponent(location.pathname.split("/").filter(Boolean).pop() ?? "");
const api = new Api(token);
const query = new URLSearchParams(location.search);
const speedParam = parseFloat(query.get("speed") ?? "1");
const retryCap = parseFloat(query.get("retry_cap") ?? "");
if (isFinite(retryCap) && retryCap >= 50) api.retry = { firstMs: Math.min(api.retry.firstMs, retryCap), capMs: retryCap };

let st: State;
let shownScore = 0; // the score on screen: it changes when the outcome is shown, not when it is known
let speed = 1;
let phase: Phase = "loading";
let current: Current | null = null;
let layout: Layout = makeLayout(1, false);
let robot: RobotState = freshRobot(layout);
let item: ItemState = freshItem(layout);
let pathS = 0;
let pathL = 1;
let phaseT = 0;
let flash = 0;
let trialEvents: UIEvent[] = [];
let teleopStart = 0;
let intervened = false;
let submissionId = "";
let outcome: TrialResult | null = null;
let hint = "";
let hintUntil = 0;
let clock = 0;
let impact: { x: number; y: number; t: number } | undefined;
let driven = 0; // teleoperation: distance driven by the base (m)
let armTravel = 0; // and by the arm
let graspAttempts = 0;
type Pending = { human: "intervene" | "rely"; effort: number | null };
let pending: Pending | null = null; // a trial being saved

function freshRobot(l: Layout): RobotState {
  return { x: l.start.x, y: l.start.y, heading: 0, arm: 0, jaw: 0.2, holding: false, binCount: 0, shake: 0 };
}
function freshItem(l: Layout): ItemState {
  return { x: l.item.x, y: l.item.y, z: 0, inBin: false, visible: true };
}

function log(type: string, data: Record<string, unknown> = {}) {
  trialEvents.push({ t: Date.now(), type, trial: current?.trial, data });
  save();
}

// --------------------------------------------------------------------------- the trial in progress, kept across reloads

interface Saved {
  trial: number; submissionId: string; events: UIEvent[]; intervened: boolean; phase: Phase;
  teleopMs: number | null; robot: RobotState; item: ItemState; pending: Pending | null;
  driven: number; armTravel: number; graspAttempts: number; contacts?: number; inputs?: number;
}
const savedKey = () => `trustseek-trial:${api.sessionId}`;
let lastSave = 0;

function save() {
  if (!current || !api.sessionId) return;
  lastSave = clock;
  const s: Saved = {
    trial: current.trial, submissionId, events: trialEvents, intervened, phase,
    teleopMs: phase === "teleop" || pending?.human === "intervene" ? performance.now() - teleopStart : null,
    robot, item, pending, driven, armTravel, graspAttempts, contacts: contacts.count, inputs,
  };
  try {
    localStorage.setItem(savedKey(), JSON.stringify(s));
  } catch {
    // storage full or disabled: the trial still goes to the server when it ends
  }
}

function savedFor(trial: number): Saved | null {
  try {
    const s = JSON.parse(localStorage.getItem(savedKey()) ?? "null") as Saved | null;
    return s && s.trial === trial && typeof s.submissionId === "string" && Array.isArray(s.events) ? s : null;
  } catch {
    return null;
  }
}

function forget() {
  try {
    localStorage.removeItem(savedKey());
  } catch {
    // nothing kept
  }
}

let retries = 0; // requests repeated since the page was opened (the test of outages reads it)
function onConnection(c: Connection) {
  if (c === "retrying") retries++;
  $("connection").hidden = c === "ok";
}

function setPhase(p: Phase) {
  phase = p;
  phaseT = 0;
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
  if (p === "report" || p === "questionnaire" || p === "done") hintUntil = 0;
  renderStatus();
}

/** A problem the participant can act on (the page goes on). */
function showError(msg: string) {
  const e = $("error");
  e.textContent = msg;
  e.hidden = false;
}

function clearError() {
  $("error").hidden = true;
}

/** A problem that stops the study on this page: a screen of its own, not a blank page. */
function showFatal(title: string, msg: string) {
  $("error-title").textContent = title;
  $("error-text").textContent = msg;
  setPhase("error");
}

/** Phones and tablets without a keyboard or mouse cannot teleoperate the robot. */
function touchOnly(): boolean {
  return !!window.matchMedia && window.matchMedia("(any-pointer: coarse)").matches && !window.matchMedia("(any-pointer: fine)").matches;
}

function setHint(text: string, seconds = 2.5) {
  hint = text;
  hintUntil = clock + seconds;
}

// --------------------------------------------------------------------------- flow

const TASK_PHASES: Phase[] = ["approach", "reach", "waiting", "outcome", "teleop", "result"];

async function boot() {
  if (touchOnly()) {
    showFatal(
      "Please use a computer",
      "Thank you for your interest. This study needs a keyboard (or a gamepad) and a screen of at least 1280 \u00d7 720 pixels: " +
        "please open the same link on a laptop or desktop computer. Nothing has been recorded.",
    );
    return;
  }
  installKeyboard(window, () => TASK_PHASES.includes(phase));
  api.onConnection = onConnection;
  window.addEventListener("gamepadconnected", (e) => log("gamepad_connected", { id: (e as GamepadEvent).gamepad.id }));
  window.addEventListener("pagehide", save);
  try {
    st = await api.me();
  } catch (e) {
    if (e instanceof ApiError && (e.status === 401 || e.status === 403 || e.status === 404)) {
      showFatal("This link is not valid", "Please check the address you were given, or ask the experimenter for a new link.");
    } else showFatal("The study cannot start", (e as Error).message);
    return;
  }
  speed = (st.preview && isFinite(speedParam) && speedParam > 0 ? speedParam : 1) * st.animation_speed;
  $("preview-tag").hidden = !st.preview;
  $("consent-trials").textContent = String(st.trials_total - st.practice_trials);
  useScene((st as { scene?: string }).scene);
  shownScore = st.score;
  if (st.consent_text) $("consent-text").textContent = st.consent_text;
  if (st.instructions) $("instructions-text").textContent = st.instructions;
  const rw = st.rewards;
  $("reward-auto").textContent = fmtReward(rw.autonomous_success);
  $("reward-ask").textContent = fmtReward(rw.ask);
  $("reward-int").textContent = fmtReward(rw.intervene);
  $("reward-fail").textContent = fmtReward(rw.autonomous_failure);
  $<HTMLInputElement>("agree").addEventListener("change", (e) => ($<HTMLButtonElement>("consent-btn").disabled = !(e.target as HTMLInputElement).checked));
  $("consent-btn").addEventListener("click", onConsent);
  $("start-btn").addEventListener("click", () => {
    api.events([{ t: Date.now(), type: "instructions_done" }]).catch(() => undefined);
    route();
  });
  $("intervene-btn").addEventListener("click", () => intervene("button"));
  $("report-btn").addEventListener("click", onReport);
  $("quiz-btn").addEventListener("click", onQuiz);
  $("questionnaire-btn").addEventListener("click", onQuestionnaire);
  $<HTMLInputElement>("report-slider").addEventListener("input", (e) => {
    // an answer is required: the button is enabled once the slider has been moved
    $("report-value").textContent = (e.target as HTMLInputElement).value;
    $<HTMLButtonElement>("report-btn").disabled = false;
  });
  requestAnimationFrame(frame);
  if (st.status === "new") setPhase("consent");
  else route();
}

function fmtReward(x: number) {
  return (x > 0 ? "+" : x < 0 ? "\u2212" : "") + Math.abs(x);
}

async function onConsent() {
  $<HTMLButtonElement>("consent-btn").disabled = true;
  // an online panel's ids arrive in the link's query (PROLIFIC_PID, STUDY_ID, SESSION_ID, ...)
  const query = new URLSearchParams(location.search);
  const panel: Record<string, string> = {};
  for (const k of st.panel_params) {
    const v = query.get(k);
    if (v) panel[k] = v.slice(0, 200);
  }
  $("consent-status").textContent = "Saving\u2026";
  try {
    st = await api.consent([{ t: Date.now(), type: "consent" }], panel);
  } catch (e) {
    $("consent-status").textContent = "";
    $<HTMLButtonElement>("consent-btn").disabled = !$<HTMLInputElement>("agree").checked;
    showError(`Could not save your consent: ${(e as Error).message}. Please try again.`);
    return;
  }
  $("consent-status").textContent = "";
  clearError();
  setPhase("instructions");
  $("start-btn").focus();
}

function route() {
  shownScore = st.score;
  if (st.ended) return finish();
  if (st.quiz) return askQuiz(st.quiz);
  if (st.report_due !== null) return askReport();
  if (st.questionnaire) return askQuestionnaire(st.questionnaire);
  if (st.current) return startTrial(st.current);
  finish();
}

function finish() {
  forget();
  $("final-score").textContent = String(st.score);
  $("final-trials").textContent = String(st.trials_done - st.practice_trials);
  if (st.screened) {
    $("done-title").textContent = "Thank you for your time";
    $("done-text").textContent = "The study needs every answer of the check after the instructions right, so it ends here.";
  }
  setPhase("done");
  const c = st.completion;
  if (c) {
    $("completion-code").textContent = c.code;
    $("completion").hidden = false;
    if (c.redirect_url) {
      const link = $<HTMLAnchorElement>("completion-link");
      link.href = c.redirect_url;
      link.hidden = false;
      setTimeout(() => location.assign(c.redirect_url!), 4000);
    }
  }
}

function startTrial(cur: Current) {
  current = cur;
  trialEvents = [];
  outcome = null;
  intervened = false;
  pending = null;
  const saved = savedFor(cur.trial);
  submissionId = saved?.submissionId ?? `${api.sessionId}-${cur.trial}-${Math.random().toString(36).slice(2, 10)}`;
  layout = makeLayout(cur.scene_seed, cur.complexity === "high");
  $("banner").className = "cut"; // the last trial's banner is gone before this trial starts
  const bin = robot.binCount;
  robot = freshRobot(layout);
  robot.binCount = bin;
  item = freshItem(layout);
  impact = undefined;
  pathS = 0;
  pathL = approachLength(cur.scene_seed);
  if (saved) return resumeTrial(cur, saved);
  log("trial_start", { complexity: cur.complexity, robot_action: cur.robot_action, block: cur.block });
  if (cur.robot_action === "ask") {
    teleopStart = performance.now();
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
  trialEvents = saved.events;
  intervened = saved.intervened;
  log("resumed", { phase: saved.phase });
  if (saved.pending) {
    // the trial had ended and was being saved: send it again (the same submission id)
    teleopStart = performance.now() - (saved.teleopMs ?? 0);
    Object.assign(robot, saved.robot);
    Object.assign(item, saved.item);
    sendTrial(saved.pending.human, saved.pending.effort);
    return;
  }
  if (saved.phase === "teleop" || saved.intervened) {
    Object.assign(robot, saved.robot, { shake: 0 });
    Object.assign(item, saved.item);
    driven = saved.driven;
    armTravel = saved.armTravel;
    graspAttempts = saved.graspAttempts;
    contacts.reset(saved.contacts ?? 0);
    inputs = saved.inputs ?? 0;
    teleopStart = performance.now() - (saved.teleopMs ?? 0);
    setPhase("teleop");
    setHint(cur.robot_action === "ask" ? "Welcome back: carry on helping the robot." : "Welcome back: you are still in control.", 4);
    return;
  }
  setPhase("approach"); // the robot had not finished its approach: it starts it again
}

function resetTeleop() {
  driven = 0;
  armTravel = 0;
  graspAttempts = 0;
  contacts.reset();
  inputs = 0;
}

function intervene(via: string) {
  if (phase !== "approach" && phase !== "reach") return;
  intervened = true;
  log("intervene", { via, progress: pathS / pathL, arm: robot.arm });
  teleopStart = performance.now();
  resetTeleop();
  log("teleop_start", { reason: "intervened" });
  setPhase("teleop");
  setHint("You took over: drive to the item, grasp it (G) and deposit it in the bin (B).", 4);
}

function submit(human: "intervene" | "rely") {
  sendTrial(human, human === "intervene" ? performance.now() - teleopStart : null);
}

async function sendTrial(human: "intervene" | "rely", effort: number | null) {
  const cur = current!;
  pending = { human, effort };
  setPhase(human === "rely" ? "waiting" : "result");
  save(); // a reload from here on sends the same trial again
  try {
    // retried until the server answers; the submission id makes a repeat harmless
    const res = await api.submitTrial({ trial: cur.trial, submission_id: submissionId, human_action: human, effort_ms: effort, events: trialEvents });
    outcome = res.trial;
    st = res.state;
  } catch (e) {
    if (e instanceof ApiError && e.status === 409) {
      // the server is ahead of this page (another tab, or an earlier save): follow it
      forget();
      st = await api.state().catch(() => st);
      return route();
    }
    showFatal("Your trial could not be saved", `${(e as Error).message}. Please reload the page; what you did so far is kept.`);
    return;
  }
  pending = null;
  forget();
  if (human === "rely") setPhase("outcome");
  else {
    phaseT = 0;
    showBanner();
  }
  renderStatus();
}

function showBanner() {
  const o = outcome!;
  const r = fmtReward(o.reward);
  const text: Record<string, string> = {
    success: "Collected autonomously",
    collision: "Failure: the robot collided with its surroundings",
    dropped: "Failure: the robot dropped the item",
    teleoperated: o.robot_action === "ask" ? "Collected with your help" : "You took over and collected the item",
  };
  const b = $("banner");
  b.innerHTML = `<span class="pts ${o.reward > 0 ? "pos" : o.reward < 0 ? "neg" : ""}">${r}</span> ${text[o.outcome] ?? o.outcome}${o.practice ? " (practice: not scored)" : ""}`;
  b.className = "show";
  shownScore = st.score;
  api.events([{ t: Date.now(), type: "outcome_shown", trial: o.trial, data: { outcome: o.outcome, reward: o.reward } }]).catch(() => undefined);
}

function afterResult() {
  $("banner").className = "cut";
  route();
}

function askReport() {
  $<HTMLInputElement>("report-slider").value = "50";
  $("report-value").textContent = "\u2013";
  $<HTMLButtonElement>("report-btn").disabled = true;
  $("report-scope").textContent = st.self_report === "block" ? "this block" : "this trial";
  setPhase("report");
}

async function onReport() {
  const v = Number($<HTMLInputElement>("report-slider").value);
  $<HTMLButtonElement>("report-btn").disabled = true;
  try {
    const res = await api.report(st.report_due!, v);
    st = res.state;
  } catch (e) {
    $<HTMLButtonElement>("report-btn").disabled = false;
    showError(`Could not save your answer: ${(e as Error).message}. Please try again.`);
    return;
  }
  clearError();
  route();
}

// --------------------------------------------------------------------------- the comprehension quiz

function askQuiz(q: Quiz) {
  const body = $("quiz-items");
  body.replaceChildren();
  for (const item of q.questions) {
    const row = document.createElement("fieldset");
    row.className = "quiz-item";
    const legend = document.createElement("legend");
    legend.textContent = item.text;
    row.append(legend);
    item.options.forEach((text, k) => {
      const label = document.createElement("label");
      const input = document.createElement("input");
      input.type = "radio";
      input.name = `quiz-${item.id}`;
      input.value = String(k);
      input.dataset.item = item.id;
      input.addEventListener("change", updateQuizButton);
      label.append(input, document.createTextNode(` ${text}`));
      row.append(label);
    });
    body.append(row);
  }
  $("quiz-attempt").textContent = q.attempt > 1
    ? `Some answers were not right: please read the instructions again. Attempt ${q.attempt} of ${q.attempts}.`
    : `Attempt 1 of ${q.attempts}.`;
  updateQuizButton();
  setPhase("quiz");
}

function quizAnswers(): Record<string, number> {
  const out: Record<string, number> = {};
  for (const input of Array.from(document.querySelectorAll<HTMLInputElement>("#quiz-items input:checked"))) out[input.dataset.item!] = Number(input.value);
  return out;
}

function updateQuizButton() {
  $<HTMLButtonElement>("quiz-btn").disabled = Object.keys(quizAnswers()).length < (st.quiz?.questions.length ?? 0);
}

async function onQuiz() {
  const q = st.quiz!;
  $<HTMLButtonElement>("quiz-btn").disabled = true;
  try {
    const res = await api.quiz(q.attempt, quizAnswers());
    st = res.state;
  } catch (e) {
    updateQuizButton();
    showError(`Could not save your answers: ${(e as Error).message}. Please try again.`);
    return;
  }
  clearError();
  // a wrong answer with attempts left: the instructions again, then the quiz
  if (st.quiz) {
    setPhase("instructions");
    $("instructions-again").hidden = false;
    return;
  }
  route();
}

let asked: Questionnaire | null = null;

function askQuestionnaire(q: Questionnaire) {
  asked = q;
  $("questionnaire-title").textContent = q.title || "Please answer every question.";
  const [lo, hi] = [q.scale.anchors[0] ?? String(q.scale.min), q.scale.anchors[1] ?? String(q.scale.max)];
  const body = $("questionnaire-items");
  body.replaceChildren();
  for (const item of q.items) {
    const row = document.createElement("fieldset");
    row.className = "q-item";
    const legend = document.createElement("legend");
    legend.textContent = item.text;
    row.append(legend);
    const scale = document.createElement("div");
    scale.className = "q-scale";
    const left = document.createElement("span");
    left.textContent = lo;
    scale.append(left);
    for (let v = q.scale.min; v <= q.scale.max; v++) {
      const label = document.createElement("label");
      const input = document.createElement("input");
      input.type = "radio";
      input.name = `q-${item.id}`;
      input.value = String(v);
      input.dataset.item = item.id;
      input.addEventListener("change", updateQuestionnaireButton);
      label.append(input, document.createTextNode(String(v)));
      scale.append(label);
    }
    const right = document.createElement("span");
    right.textContent = hi;
    scale.append(right);
    row.append(scale);
    body.append(row);
  }
  updateQuestionnaireButton();
  setPhase("questionnaire");
}

function questionnaireAnswers(): Record<string, number> {
  const out: Record<string, number> = {};
  for (const input of Array.from(document.querySelectorAll<HTMLInputElement>("#questionnaire-items input:checked"))) {
    out[input.dataset.item!] = Number(input.value);
  }
  return out;
}

function updateQuestionnaireButton() {
  const n = Object.keys(questionnaireAnswers()).length;
  const total = asked ? asked.items.length : 0;
  $<HTMLButtonElement>("questionnaire-btn").disabled = n < total;
  $("questionnaire-progress").textContent = `${n} of ${total} answered`;
}

async function onQuestionnaire() {
  const q = asked!;
  $<HTMLButtonElement>("questionnaire-btn").disabled = true;
  try {
    const res = await api.answer(q.name, q.after_trial, questionnaireAnswers());
    st = res.state;
  } catch (e) {
    updateQuestionnaireButton();
    showError(`Could not save your answers: ${(e as Error).message}. Please try again.`);
    return;
  }
  clearError();
  route();
}

// --------------------------------------------------------------------------- per frame

let last = performance.now();
function frame(now: number) {
  const dt = Math.min(0.1, (now - last) / 1000); // a slow frame (software WebGL) still keeps time
  last = now;
  if (!manual) {
    tick(dt);
    draw();
    renderStatus();
  }
  requestAnimationFrame(frame);
}

/** The page's state `dt` seconds on (the clock of the animations and of the teleoperation). */
function tick(dt: number) {
  clock += dt;
  const cmd = poll();
  const k = dt * speed;
  phaseT += k;
  flash = Math.max(0, flash - dt * 1.5);
  robot.shake = Math.max(0, robot.shake - dt * 2);

  if (phase === "approach" || phase === "reach") {
    if (cmd.intervene) intervene(cmd.interveneVia ?? "key");
  }
  if (phase === "approach") {
    pathS = Math.min(pathL, pathS + 1.7 * k);
    const p = approachPose(pathS);
    robot.x = p.x;
    robot.y = p.y;
    robot.heading = p.heading;
    if (pathS >= pathL) {
      setPhase("reach");
      robot.heading = 0;
    }
  } else if (phase === "reach") {
    robot.jaw = Math.min(1, robot.jaw + 2 * k);
    robot.arm = Math.min(layout.reachExtension, robot.arm + 1.1 * k);
    if (robot.arm >= layout.reachExtension) {
      log("grasp", { by: "robot" });
      submit("rely");
    }
  } else if (phase === "outcome") {
    if (!scene3d) animateOutcome(k);
    else if (scene3d.outcome(outcome!.outcome, phaseT, k, robot, item)) toResult();
  } else if (phase === "teleop") {
    teleop(cmd, k);
    if (clock - lastSave > 0.5) save();
  } else if (phase === "result") {
    if (outcome && phaseT > 1.6) afterResult();
  }
}

function animateOutcome(k: number) {
  const o = outcome!;
  const t = phaseT;
  const gp = gripperPos(robot, layout.side);
  if (o.outcome === "success") {
    if (t < 0.3) robot.jaw = Math.max(0, 1 - t / 0.3);
    else {
      robot.holding = true;
      robot.arm = Math.max(0, robot.arm - 1.4 * k);
      item.x = gp.x;
      item.y = gp.y;
      if (robot.arm <= 0) {
        item.inBin = true;
        robot.holding = false;
        robot.binCount++;
        toResult();
      }
    }
  } else if (o.outcome === "collision") {
    // the base swerves into the shelf: a jolt, a flash, the arm pulls back
    const edge = layout.side < 0 ? SHELF_DEPTH + BASE_H / 2 : AISLE_H - SHELF_DEPTH - BASE_H / 2;
    if (!impact) {
      robot.y += (edge - robot.y) * Math.min(1, 6 * k);
      if (Math.abs(edge - robot.y) < 0.02 || t > 0.4) {
        robot.y = edge;
        impact = { x: robot.x + 0.3, y: layout.side < 0 ? SHELF_DEPTH : AISLE_H - SHELF_DEPTH, t: 0 };
        flash = 1;
        robot.shake = 1;
      }
    } else impact.t += k;
    robot.arm = Math.max(0, robot.arm - 0.8 * k);
    if (t > 1.4) toResult();
  } else {
    // dropped: grasp, lift, lose it on the way to the bin
    if (t < 0.3) robot.jaw = Math.max(0, 1 - t / 0.3);
    else if (t < 0.8) {
      robot.holding = true;
      robot.arm = Math.max(0, robot.arm - 1.2 * k);
      item.x = gp.x;
      item.y = gp.y;
    } else {
      if (robot.holding) {
        robot.holding = false;
        robot.jaw = 1;
        flash = 0.8;
      }
      // it falls to the floor beside the robot, out of reach
      const fx = robot.x + 0.8, fy = robot.y;
      item.x += (fx - item.x) * Math.min(1, 4 * k);
      item.y += (fy - item.y) * Math.min(1, 4 * k);
      if (t > 1.6) toResult();
    }
  }
}

function toResult() {
  setPhase("result");
  showBanner();
}

function teleop(cmd: ReturnType<typeof poll>, k: number) {
  const v = 1.8;
  // the 2-D robot faces where it drives; the 3-D one drives sideways too (its wheels are omnidirectional)
  if (cmd.vx || cmd.vy) robot.heading = scene3d ? 0 : Math.atan2(cmd.vy, cmd.vx);
  const x0 = robot.x, y0 = robot.y, a0 = robot.arm;
  robot.x += cmd.vx * v * k;
  robot.y += cmd.vy * v * k;
  const hit = clampRobot(robot, layout);
  robot.arm = Math.max(0, Math.min(ARM_MAX, robot.arm + cmd.arm * 1.0 * k));
  if (cmd.vx || cmd.vy || cmd.arm) inputs++;
  touch(hit, a0, cmd.vx, cmd.vy);
  driven += Math.hypot(robot.x - x0, robot.y - y0);
  armTravel += Math.abs(robot.arm - a0);
  const gp = gripperPos(robot, layout.side);
  if (robot.holding) {
    item.x = gp.x;
    item.y = gp.y;
  } else if (!robot.holding) robot.jaw = Math.min(1, robot.jaw + 2 * k);
  if (cmd.grasp) {
    graspAttempts++;
    if (robot.holding) setHint("Already holding the item: retract the arm (X) and deposit it (B).");
    else if (Math.hypot(gp.x - item.x, gp.y - item.y) <= REACH && (scene3d?.around(item) ?? true)) {
      robot.holding = true;
      robot.jaw = 0;
      log("grasp", { by: "human" });
    } else {
      log("grasp_missed", { distance: Math.hypot(gp.x - item.x, gp.y - item.y) });
      setHint("Too far: bring the gripper (orange) onto the item first.");
    }
  }
  if (cmd.deposit) {
    if (!robot.holding) setHint("Grasp the item first (G).");
    else if (robot.arm > 0.3) {
      log("deposit_refused", { arm: robot.arm });
      setHint("Retract the arm (X) before depositing.");
    }
    else {
      robot.holding = false;
      item.inBin = true;
      robot.binCount++;
      log("deposit", { seconds: (performance.now() - teleopStart) / 1000, driven_m: +driven.toFixed(3), arm_m: +armTravel.toFixed(3), grasp_attempts: graspAttempts, contacts: contacts.count, inputs, gamepad: gamepadName() });
      submit("intervene");
    }
  }
}

// --------------------------------------------------------------------------- the 3-D scene (scene3d/)
// The views are drawn in 3-D where WebGL works and the study does not ask for the 2-D scene
// (`"scene": "2d"`, or `?scene=2d`); the session records which scene ran (a "scene" event).
// `?quality=0..4` fixes the 3-D detail; `?manual=1` stops the page's clock: the tests then move
// it with window.__scene.step(seconds, frames), never by the wall clock.

let scene3d: Scene3D | null = null;
let manual = query.get("manual") === "1";
const APPROACH_V = 1.7; // the rate of pathS (m/s), as the 2-D scene drives
const contacts = new Contacts(); // teleoperation: contacts with shelves, products and obstacles
let inputs = 0; // and frames with a drive or arm input

function useScene(asked: string | undefined) {
  const c = chooseScene(query, asked, { world: $<HTMLCanvasElement>("world"), local: $<HTMLCanvasElement>("local"), ee: $<HTMLCanvasElement>("ee") });
  scene3d = c.scene;
  document.body.dataset.scene = c.ran;
  api.events([{ t: Date.now(), type: "scene", data: { scene: c.ran, asked: c.asked, reason: c.reason } }]).catch(() => undefined);
}

function approachLength(seed: number): number {
  if (!scene3d) return pathLength(layout.path);
  scene3d.setTrial(layout, seed, item);
  return scene3d.drive.duration * APPROACH_V;
}

function approachPose(s: number) {
  return scene3d ? scene3d.drivePose(s / APPROACH_V) : pointAlong(layout.path, s);
}

/** A contact of the base, or of the arm in 3-D (the arm then stays where it was): logged when it begins. */
function touch(baseHit: string | null, a0: number, vx: number, vy: number) {
  const armHit = scene3d?.teleopArm(robot, item) ?? null;
  if (armHit) robot.arm = a0;
  const hit = armHit ?? baseHit;
  if (contacts.touch(hit, clock, robot, layout, vx, vy)) {
    log("contact", { with: hit, x: +robot.x.toFixed(3), y: +robot.y.toFixed(3), arm: +robot.arm.toFixed(3) });
    if (scene3d) robot.shake = 0.6;
  }
}

(window as unknown as { __scene: unknown }).__scene = {
  scene: () => (scene3d ? "3d" : "2d"),
  /** Stop (true) or restart (false) the page's own clock. */
  manual: (on: boolean) => {
    manual = on;
    last = performance.now();
  },
  /** Move the page's clock on by `frames` frames of `dt` seconds; draw the last one unless `render` is false. */
  step: (dt: number, frames = 1, render = true) => {
    for (let i = 0; i < frames; i++) tick(dt);
    if (render) draw();
    renderStatus();
    return scene3d?.state() ?? null;
  },
  state: () => scene3d?.state() ?? null,
};

// --------------------------------------------------------------------------- drawing and status

function view(): View {
  const asking = phase === "teleop" && !intervened && !robot.holding && !item.inBin;
  return { layout, robot, item, showPath: phase === "approach", flash, highlight: !robot.holding && !item.inBin, time: clock, bubble: asking ? "Please help me!" : undefined, impact, picks: picks() };
}

/** The items left in a block whose policy picks them, the one of this trial marked (until it is in the bin). */
function picks() {
  const items = current?.items;
  if (!items) return undefined;
  const tokens = pickTokens(items, current!.complexity, ["low", "high"]);
  if (!item.inBin) return tokens;
  const i = tokens.findIndex((t) => t.next);
  return tokens.filter((_, k) => k !== i);
}

function draw() {
  const v = view();
  if (scene3d) return scene3d.draw(v, phase);
  drawWorld($<HTMLCanvasElement>("world"), v);
  drawLocal($<HTMLCanvasElement>("local"), v);
  drawEndEffector($<HTMLCanvasElement>("ee"), v);
}

let lastStatus = "";
function renderStatus() {
  if (!st) return;
  const trial = current ? current.trial : st.trials_done;
  let mode = "";
  let cls = "";
  if (phase === "approach" || phase === "reach" || phase === "waiting" || (phase === "outcome" && current?.robot_action === "autonomous")) {
    mode = "Collecting autonomously";
    cls = "auto";
  } else if (phase === "teleop") {
    mode = intervened ? "You are in control (intervention)" : "Asking for your help";
    cls = intervened ? "teleop" : "ask";
  } else if (phase === "result") {
    mode = "Trial complete";
    cls = "idle";
  } else if (phase === "report" || phase === "questionnaire") {
    mode = "Your rating, please";
    cls = "idle";
  }
  const gp = gripperPos(robot, layout.side);
  const near = Math.hypot(gp.x - item.x, gp.y - item.y) <= REACH;
  let h = clock < hintUntil ? hint : "";
  if (!h && phase === "teleop") {
    h = robot.holding ? (robot.arm > 0.3 ? "Retract the arm (X), then deposit (B)." : "Press B to deposit the item in the bin.") : near ? "Item within reach: press G to grasp." : "Drive (arrows/WASD) and extend the arm (Z) to reach the item.";
  }
  if (!h && (phase === "approach" || phase === "reach")) h = "Watch the robot. Intervene (Space) if you think it will fail.";
  const pad = gamepadName();
  const key = [trial, st.trials_total, shownScore, mode, cls, h, pad, phase, current?.complexity].join("|");
  if (key === lastStatus) return;
  lastStatus = key;
  // practice trials are counted apart: the study's trials run 1..N as the end page counts them
  const np = st.practice_trials;
  const practice = current ? current.practice : trial <= np;
  $("trial-no").textContent = practice ? `${trial} / ${np}` : `${Math.max(0, trial - np)} / ${st.trials_total - np}`;
  $("score").textContent = String(shownScore);
  const m = $("mode");
  m.textContent = mode;
  m.className = `mode ${cls}`;
  $("hint").textContent = h;
  $("block-name").textContent = !current ? "" : current.practice ? "Practice trial (not scored)" : `Block ${current.block_position} of ${st.blocks.length}`;
  $("gamepad").textContent = pad ? `Gamepad: ${pad.slice(0, 40)}` : "No gamepad (keyboard works)";
  $<HTMLButtonElement>("intervene-btn").disabled = !(phase === "approach" || phase === "reach");
}

(window as unknown as { trustseek: unknown }).trustseek = {
  state: () => ({
    phase, trial: current?.trial ?? null, robot_action: current?.robot_action ?? null, complexity: current?.complexity ?? null,
    robot: { x: robot.x, y: robot.y, arm: robot.arm, holding: robot.holding }, item: { x: item.x, y: item.y, inBin: item.inBin },
    gripper: gripperPos(robot, layout.side), reach: REACH, side: layout.side, score: st?.score ?? null, shown_score: shownScore,
    practice: current?.practice ?? null, picks: picks() ?? null, speed, trial_label: $("trial-no").textContent, retries, connection: $("connection").hidden ? "ok" : "retrying",
  }),
};

boot();
