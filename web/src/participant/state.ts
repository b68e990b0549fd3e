// The participant page's state, shared by its modules: the study's state from the server, the
// trial in progress (kept in localStorage across reloads), the page's clock and its messages.

import { Api, Connection, Current, State, TrialResult, UIEvent, uiEvent } from "../api";
import { Outcome2D } from "../outcome2d";
import { ItemState, Layout, RobotState, makeLayout } from "../scene";
import { Scene3D } from "../scene3d";
import { Contacts } from "../scene3d/page";

export type Phase = "loading" | "consent" | "instructions" | "quiz" | "approach" | "reach" | "waiting" | "outcome" | "teleop" | "result" | "report" | "questionnaire" | "done" | "error";

export const $ = <T extends HTMLElement = HTMLElement>(id: string) => document.getElementById(id) as T;
const token = decodeURIComponent(location.pathname.split("/").filter(Boolean).pop() ?? "");
export const api = new Api(token);
export const query = new URLSearchParams(location.search);
export const speedParam = parseFloat(query.get("speed") ?? "1");
const retryCap = parseFloat(query.get("retry_cap") ?? "");
if (isFinite(retryCap) && retryCap >= 50) api.retry = { firstMs: Math.min(api.retry.firstMs, retryCap), capMs: retryCap };

export type Pending = { human: "intervene" | "rely"; effort: number | null };

export function freshRobot(l: Layout): RobotState {
  return { x: l.start.x, y: l.start.y, heading: 0, arm: 0, jaw: 0.2, holding: false, binCount: 0, shake: 0 };
}
export function freshItem(l: Layout): ItemState {
  return { x: l.item.x, y: l.item.y, z: 0, inBin: false, visible: true };
}

const layout0 = makeLayout(1, false);
export const page = {
  st: undefined as unknown as State,
  shownScore: 0, // the score on screen: it changes when the outcome is shown, not when it is known
  speed: 1,
  phase: "loading" as Phase,
  current: null as Current | null,
  layout: layout0 as Layout,
  robot: freshRobot(layout0),
  item: freshItem(layout0),
  pathS: 0,
  pathL: 1,
  phaseT: 0,
  flash: 0,
  trialEvents: [] as UIEvent[],
  teleopStart: 0,
  intervened: false,
  submissionId: "",
  outcome: null as TrialResult | null,
  hint: "",
  hintUntil: 0,
  clock: 0,
  impact: undefined as { x: number; y: number; t: number } | undefined,
  driven: 0, // teleoperation: distance driven by the base (m)
  armTravel: 0, // and by the arm
  graspAttempts: 0,
  pending: null as Pending | null, // a trial being saved
  lastSave: 0,
  retries: 0, // requests repeated since the page was opened (the test of outages reads it)
  scene3d: null as Scene3D | null,
  anim2d: null as Outcome2D | null, // the 2-D scene's outcome animation
  manual: query.get("manual") === "1",
  inputs: 0, // teleoperation: frames with a drive or arm input
  /** the study's next screen (set by the page's flow) */
  route: (() => undefined) as () => void,
};
export const contacts = new Contacts(); // teleoperation: contacts with shelves, products and obstacles

export function log(type: string, data: Record<string, unknown> = {}) {
  page.trialEvents.push(uiEvent(type, data, page.current?.trial));
  save();
}

// --------------------------------------------------------------------------- the trial in progress, kept across reloads

export interface Saved {
  trial: number; submissionId: string; events: UIEvent[]; intervened: boolean; phase: Phase;
  teleopMs: number | null; robot: RobotState; item: ItemState; pending: Pending | null;
  driven: number; armTravel: number; graspAttempts: number; contacts?: number; inputs?: number;
}
const savedKey = () => `trustseek-trial:${api.sessionId}`;

export function save() {
  if (!page.current || !api.sessionId) return;
  page.lastSave = page.clock;
  const s: Saved = {
    trial: page.current.trial, submissionId: page.submissionId, events: page.trialEvents, intervened: page.intervened, phase: page.phase,
    teleopMs: page.phase === "teleop" || page.pending?.human === "intervene" ? performance.now() - page.teleopStart : null,
    robot: page.robot, item: page.item, pending: page.pending, driven: page.driven, armTravel: page.armTravel,
    graspAttempts: page.graspAttempts, contacts: contacts.count, inputs: page.inputs,
  };
  try {
    localStorage.setItem(savedKey(), JSON.stringify(s));
  } catch {
    // storage full or disabled: the trial still goes to the server when it ends
  }
}

export function savedFor(trial: number): Saved | null {
  try {
    const s = JSON.parse(localStorage.getItem(savedKey()) ?? "null") as Saved | null;
    return s && s.trial === trial && typeof s.submissionId === "string" && Array.isArray(s.events) ? s : null;
  } catch {
    return null;
  }
}

export function forget() {
  try {
    localStorage.removeItem(savedKey());
  } catch {
    // nothing kept
  }
}

export function onConnection(c: Connection) {
  if (c === "retrying") page.retries++;
  $("connection").hidden = c === "ok";
}

/** A problem the participant can act on (the page goes on). */
export function showError(msg: string) {
  const e = $("error");
  e.textContent = msg;
  e.hidden = false;
}

export function clearError() {
  $("error").hidden = true;
}

/** Phones and tablets without a keyboard or mouse cannot teleoperate the robot. */
export function touchOnly(): boolean {
  return !!window.matchMedia && window.matchMedia("(any-pointer: coarse)").matches && !window.matchMedia("(any-pointer: fine)").matches;
}

export function setHint(text: string, seconds = 2.5) {
  page.hint = text;
  page.hintUntil = page.clock + seconds;
}

export function fmtReward(x: number) {
  return (x > 0 ? "+" : x < 0 ? "\u2212" : "") + Math.abs(x);
}
