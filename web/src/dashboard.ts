// The experimenter's live dashboard: per participant, the trial, the robot action, the human
// action, the outcome, the score and the current trust belief; refreshed every second.

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
    refresh();
  } catch (e) {
    err(`Cannot list studies: ${(e as Error).message}`);
  }
}

interface Row {
  participant: string; status: string; trials_done: number; trials_total: number; score: number; belief: number | null; link: string;
  current: { trial: number; complexity: string; robot_action: string } | null;
  last: { trial: number; complexity: string; robot_action: string; human_action: string | null; outcome: string; reward: number } | null;
  last_self_report: number | null;
}

async function refresh() {
  if (!token || !study) return;
  try {
    const d = await (await call(`/api/studies/${study}/dashboard`)).json();
    const s = d.study;
    $("summary").textContent = `${s.name}: ${s.blocks.map((b: { name: string; policy: string }) => `${b.name} (${b.policy})`).join(", ")}; counterbalance ${s.counterbalance}; self-report ${s.self_report}; ${s.participants} participants`;
    const rows: Row[] = d.participants;
    $("rows").innerHTML = rows.length ? rows.map((r) => {
      const t = r.last;
      const b = r.belief;
      return `<tr><td>${esc(r.participant)}</td><td><span class="pill ${esc(r.status)}">${esc(r.status)}</span></td>
        <td>${r.trials_done} / ${r.trials_total}${r.current ? ` <span class="muted">(now ${r.current.trial}: ${esc(r.current.robot_action)})</span>` : ""}</td>
        <td>${esc(t?.complexity ?? "")}</td><td>${esc(t?.robot_action ?? "")}</td><td>${esc(t?.human_action ?? "")}</td>
        <td>${esc(t?.outcome ?? "")}${t ? ` <span class="muted">(${t.reward > 0 ? "+" : ""}${t.reward})</span>` : ""}</td>
        <td>${r.score}</td>
        <td>${b === null ? "" : `<span class="bar"><i style="width:${(b * 100).toFixed(0)}%"></i></span>${b.toFixed(2)}`}</td>
        <td>${r.last_self_report ?? ""}</td>
        <td><a href="${esc(r.link)}" target="_blank" rel="noreferrer">open</a></td></tr>`;
    }).join("") : `<tr><td colspan="11" class="muted">No participants yet: create a link.</td></tr>`;
    err(null);
  } catch (e) {
    err(`Dashboard: ${(e as Error).message}`);
  }
}

async function download(table: string) {
  const res = await call(`/api/studies/${study}/export?table=${table}&format=csv`);
  const url = URL.createObjectURL(await res.blob());
  const a = document.createElement("a");
  a.href = url;
  a.download = `${study}-${table}.csv`;
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
$("new-session").addEventListener("click", async () => {
  try {
    await call(`/api/studies/${study}/sessions`, { method: "POST", body: JSON.stringify({ count: 1 }) });
    refresh();
  } catch (e) { err((e as Error).message); }
});
$("export-csv").addEventListener("click", () => download("trials").catch((e) => err(e.message)));
$("export-events").addEventListener("click", () => download("events").catch((e) => err(e.message)));
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
