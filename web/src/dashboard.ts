// The experimenter's live dashboard: the study's status, link and overall progress with its
// lifecycle (open, pause, close), preview (not recorded), pilot links and the data bundle; per participant the
// status, panel id, start, end, last activity, trial, robot and human action, outcome, score and
// current trust belief; refreshed every second.

import { describeDetail } from "./api";

const $ = <T extends HTMLElement = HTMLElement>(id: string) => document.getElementById(id) as T;
let token = sessionStorage.getItem("trustseek-token") ?? "";
let study = "";

/** A refused request: its problems, one sentence each. */
class Refused extends Error {
  constructor(public status: number, public problems: string[]) { super(problems.join("; ") || `error ${status}`); }
}

async function call(path: string, init: RequestInit = {}): Promise<Response> {
  let res: Response;
  try {
    res = await fetch(path, { ...init, headers: { Authorization: `Bearer ${token}`, "Content-Type": "application/json" } });
  } catch {
    throw new Refused(0, ["the server cannot be reached"]);
  }
  if (!res.ok) {
    const d = await res.json().catch(() => ({ detail: res.statusText }));
    const problems = describeDetail((d as { detail?: unknown }).detail);
    throw new Refused(res.status, res.status === 401 ? ["the experimenter token is not valid"] : problems);
  }
  return res;
}

/** Show a refused study: a heading and one list item per problem. */
function showProblems(el: HTMLElement, title: string, problems: string[]) {
  const head = document.createElement("p");
  head.textContent = title;
  const list = document.createElement("ul");
  for (const p of problems) {
    const li = document.createElement("li");
    li.textContent = p;
    list.append(li);
  }
  el.replaceChildren(head, list);
}

function err(msg: string | null) {
  const e = $("error");
  e.hidden = !msg;
  e.textContent = msg ?? "";
}

function esc(s: unknown): string {
  return String(s ?? "").replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" })[c]!);
}

async function loadStudies() {
  if (!token) return;
  try {
    const studies = await (await call("/api/studies")).json();
    const sel = $<HTMLSelectElement>("study");
    sel.innerHTML = studies.map((s: { id: string; name: string }) => `<option value="${esc(s.id)}">${esc(s.name)} (${esc(s.id)})</option>`).join("");
    if (!study && studies.length) study = studies[studies.length - 1].id;
    sel.value = study;
    err(null);
    if (!studies.length) {
      // a valid token with no study yet: say what to do next, not to enter the token again
      $("summary").textContent = "";
      $("rows").innerHTML = `<tr><td colspan="${COLS}" class="muted">No study yet: create one with New study\u2026</td></tr>`;
    }
    refresh();
  } catch (e) {
    err(`Cannot list studies: ${(e as Error).message}`);
  }
}

const COLS = 13;

interface Row {
  participant: string; session_id: string; status: string; role: string; panel_id: string | null; revoked: boolean;
  started_at: string | null; ended_at: string | null; last_activity: string;
  trials_done: number; trials_total: number; practice_trials: number; score: number; belief: number | null; link: string;
  current: { trial: number; complexity: string; robot_action: string } | null;
  last: { trial: number; complexity: string; robot_action: string; human_action: string | null; outcome: string; reward: number; practice: boolean } | null;
  last_self_report: number | null;
}

/** A server time (ISO, UTC) as the local clock shows it, or how long ago when within a day. */
function when(iso: string | null, now: number): string {
  if (!iso) return "";
  const t = Date.parse(iso);
  const ago = Math.max(0, Math.round((now - t) / 1000));
  if (ago < 60) return `${ago} s ago`;
  if (ago < 3600) return `${Math.round(ago / 60)} min ago`;
  return new Date(t).toLocaleString();
}

/** What the human did: when the robot asked, the participant teleoperated (stored as intervene). */
function humanAction(t: Row["last"]): string {
  if (!t) return "";
  return t.robot_action === "ask" ? "teleoperated (asked)" : t.human_action ?? "";
}

interface Summary {
  name: string; status: string; link: string | null; quota: number | null; participants: number;
  progress: Record<string, number>; blocks: { name: string; policy: string }[]; counterbalance: string; self_report: string;
}

function renderSummary(s: Summary) {
  const p = s.progress;
  const total = s.quota ?? s.participants;
  const pct = total ? Math.round((100 * p.done) / total) : 0;
  $("study-status").textContent = s.status;
  $("study-status").className = `pill ${s.status}`;
  $<HTMLAnchorElement>("study-link").textContent = s.link ?? "";
  $<HTMLAnchorElement>("study-link").href = s.link ?? "#";
  $("progress").innerHTML = `<span class="bar wide"><i style="width:${pct}%"></i></span>
    <b>${p.done}</b> done, <b>${p.running}</b> running, <b>${p.new}</b> not yet started${s.quota ? ` of a quota of <b>${s.quota}</b>` : ""}${p.screened ? `, ${p.screened} screened out` : ""}${p.revoked ? `, ${p.revoked} revoked` : ""}${p.pilot ? `; ${p.pilot} pilot` : ""}`;
  $("summary").textContent = `${s.name}: ${s.blocks.map((b) => `${b.name} (${b.policy})`).join(", ")}; counterbalance ${s.counterbalance}; self-report ${s.self_report}`;
  for (const [id, to] of [["open-study", "open"], ["pause-study", "paused"], ["close-study", "closed"]] as const) {
    const allowed: Record<string, string[]> = { draft: ["open", "closed"], open: ["paused", "closed"], paused: ["open", "closed"], closed: [] };
    $<HTMLButtonElement>(id).disabled = !(allowed[s.status] ?? []).includes(to);
  }
}

/** A trial's number as the participant's page shows it: practice trials apart from the study's. */
function trialLabel(r: Row, n: number): string {
  return n <= r.practice_trials ? `practice ${n}` : String(n - r.practice_trials);
}

/** Study trials done of the study's (practice trials are not counted, as on the participant's end page). */
function progressOf(r: Row): string {
  const np = r.practice_trials;
  if (r.trials_done < np) return `practice ${r.trials_done} / ${np}`;
  return `${r.trials_done - np} / ${r.trials_total - np}`;
}

function renderRow(r: Row, now: number): string {
  const t = r.last;
  const b = r.belief;
  const status = r.revoked ? "revoked" : r.status;
  return `<tr><td>${esc(r.participant)}${r.role === "pilot" ? ' <span class="pill pilot">pilot</span>' : ""}</td>
    <td>${esc(r.panel_id ?? "")}</td><td><span class="pill ${esc(status)}">${esc(status)}</span></td>
    <td>${progressOf(r)}${r.current ? ` <span class="muted">(now ${trialLabel(r, r.current.trial)}: ${esc(r.current.robot_action)})</span>` : ""}</td>
    <td>${esc(when(r.started_at, now))}</td><td>${esc(when(r.ended_at, now))}</td><td>${esc(when(r.last_activity, now))}</td>
    <td>${esc(t?.complexity ?? "")} ${esc(t?.robot_action ?? "")}</td><td>${esc(humanAction(t))}</td>
    <td>${esc(t?.outcome ?? "")}${t ? ` <span class="muted">(${t.practice ? "practice" : `${t.reward > 0 ? "+" : ""}${t.reward}`})</span>` : ""}</td>
    <td>${r.score}</td>
    <td>${b === null ? "" : `<span class="bar"><i style="width:${(b * 100).toFixed(0)}%"></i></span>${b.toFixed(2)}`}${r.last_self_report !== null ? ` <span class="muted">(said ${r.last_self_report})</span>` : ""}</td>
    <td><a href="${esc(r.link)}" target="_blank" rel="noreferrer">link</a>${r.revoked ? "" : ` <button class="small-btn" data-revoke="${esc(r.session_id)}">revoke</button>`}</td></tr>`;
}

async function refresh() {
  if (!token || !study) return;
  try {
    const d = await (await call(`/api/studies/${study}/dashboard`)).json();
    renderSummary(d.study);
    const rows: Row[] = d.participants;
    const now = Date.parse(d.time);
    $("rows").innerHTML = rows.length ? rows.map((r) => renderRow(r, now)).join("")
      : `<tr><td colspan="${COLS}" class="muted">No participants yet: share the study link, or make a participant link.</td></tr>`;
    $("study-bar").hidden = false;
    err(null);
  } catch (e) {
    err(`Dashboard: ${(e as Error).message}`);
  }
}

async function post(path: string, body: unknown = undefined) {
  return (await call(path, { method: "POST", body: body === undefined ? undefined : JSON.stringify(body) })).json();
}

async function download(path: string, name: string) {
  const res = await call(path);
  const url = URL.createObjectURL(await res.blob());
  const a = document.createElement("a");
  a.href = url;
  a.download = name;
  a.click();
  URL.revokeObjectURL(url);
}

$<HTMLInputElement>("token").value = token;
$("token").addEventListener("change", (e) => {
  token = (e.target as HTMLInputElement).value.trim();
  sessionStorage.setItem("trustseek-token", token);
  loadStudies();
});
$("study").addEventListener("change", (e) => { study = (e.target as HTMLSelectElement).value; refresh(); });
function act(id: string, run: () => Promise<unknown>) {
  $(id).addEventListener("click", () => run().then(refresh).catch((e) => err((e as Error).message)));
}
act("new-session", () => post(`/api/studies/${study}/sessions`, { count: 1 }));
act("new-pilot", () => post(`/api/studies/${study}/sessions`, { count: 1, pilot: true }));
act("preview", async () => window.open((await post(`/api/studies/${study}/preview`)).link, "_blank", "noreferrer"));
act("open-study", () => post(`/api/studies/${study}/status`, { status: "open" }));
act("pause-study", () => post(`/api/studies/${study}/status`, { status: "paused" }));
act("close-study", async () => {
  if (confirm("Close the study for good? Started sessions may finish; no one new can join.")) await post(`/api/studies/${study}/status`, { status: "closed" });
});
act("export-bundle", () => download(`/api/studies/${study}/bundle`, `${study}-bundle.zip`));
act("export-csv", () => download(`/api/studies/${study}/export?table=trials&format=csv`, `${study}-trials.csv`));
$("rows").addEventListener("click", (e) => {
  const id = (e.target as HTMLElement).dataset?.revoke;
  if (id && confirm("Revoke this participant's link? It will show a page saying so.")) {
    post(`/api/studies/${study}/sessions/${id}/revoke`).then(refresh).catch((x) => err((x as Error).message));
  }
});
const EXAMPLE = {
  name: "pilot",
  task: "paper",
  model: "paper",
  blocks: [
    { name: "trust-agnostic", policy: { kind: "trust-agnostic" }, schedule: { counts: { low: 10, high: 10 } } },
    { name: "trust-aware", policy: { kind: "trust-aware" }, schedule: { counts: { low: 10, high: 10 } } },
  ],
  counterbalance: "rotate",
  self_report: "block",
  animation_speed: 1.0,
  seed: 1,
};
$<HTMLTextAreaElement>("study-json").value = JSON.stringify(EXAMPLE, null, 2);
$("new-study-toggle").addEventListener("click", () => ($("new-study").hidden = !$("new-study").hidden));
$("create-study").addEventListener("click", async () => {
  const msg = $("create-msg");
  let body: unknown;
  try {
    body = JSON.parse($<HTMLTextAreaElement>("study-json").value);
  } catch (e) {
    showProblems(msg, "The study is not valid JSON:", [(e as Error).message]);
    return;
  }
  msg.textContent = "Creating (solving the policies)...";
  try {
    const st = await (await call("/api/studies", { method: "POST", body: JSON.stringify(body) })).json();
    msg.textContent = `Created ${st.name} (${st.id}).`;
    study = st.id;
    $("new-study").hidden = true;
    loadStudies();
  } catch (e) {
    showProblems(msg, "The study was not created:", e instanceof Refused ? e.problems : [(e as Error).message]);
  }
});
loadStudies();
setInterval(refresh, 1000);
