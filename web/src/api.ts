// The participant API (see docs/experiments.md): the session token from the link authorizes
// every call.  Trial submissions carry a client-made submission id, so a retry after a network
// error cannot create a second trial; event batches carry an id too, and are kept in the page's
// storage until the server answers, so that a reloaded page sends what the last one left.

export interface Current { trial: number; block: number; block_position: number; practice: boolean; complexity: string; robot_action: "autonomous" | "ask"; scene_seed: number;
  items?: { remaining: Record<string, number>; visible: Record<string, number> | null }; // a block whose policy picks the items
}
export interface Questionnaire {
  name: string; when: "trial" | "block" | "end"; title: string; after_trial: number;
  scale: { min: number; max: number; anchors: string[] }; items: { id: string; text: string }[];
}
export interface Quiz {
  attempt: number; attempts: number; wrong: string[]; questions: { id: string; text: string; options: string[] }[];
}
export interface State {
  session_id: string; participant: string; status: "new" | "running" | "done"; study: string;
  trials_total: number; trials_done: number; score: number; blocks: string[];
  current: Current | null; report_due: number | null; self_report: "none" | "trial" | "block";
  questionnaire: Questionnaire | null; quiz: Quiz | null; screened: boolean; ended: boolean; completion: { code: string; redirect_url: string | null } | null;
  panel_params: string[]; practice_trials: number;
  animation_speed: number; preview: boolean; consent_text: string | null; instructions: string | null;
  rewards: { autonomous_success: number; ask: number; intervene: number; autonomous_failure: number };
}
export interface TrialResult {
  // what the page learns of a committed trial: never the trust belief or the experience
  trial: number; complexity: string; robot_action: string; human_action: string | null; outcome: string;
  reward: number; practice: boolean;
}
export interface UIEvent { t: number; type: string; trial?: number; page?: string; data?: Record<string, unknown>; }

export class ApiError extends Error {
  constructor(public status: number, message: string) { super(message); }
}

/** A readable sentence from an error body's `detail`: a string, `{problems: [...]}` (a study or
 * a model that fails validation) or FastAPI's list of `{loc, msg}` (a malformed request). */
export function describeDetail(detail: unknown): string[] {
  if (typeof detail === "string") return [detail];
  if (Array.isArray(detail)) {
    return detail.map((d) => {
      if (d && typeof d === "object" && "msg" in d) {
        const loc = Array.isArray((d as { loc?: unknown }).loc) ? ((d as { loc: unknown[] }).loc).filter((x) => x !== "body").join(".") : "";
        return loc ? `${loc}: ${String((d as { msg: unknown }).msg)}` : String((d as { msg: unknown }).msg);
      }
      return typeof d === "string" ? d : JSON.stringify(d);
    });
  }
  if (detail && typeof detail === "object" && Array.isArray((detail as { problems?: unknown }).problems)) {
    return ((detail as { problems: unknown[] }).problems).map((x) => String(x));
  }
  return detail === undefined || detail === null ? [] : [JSON.stringify(detail)];
}

/** The connection as the page should show it: `ok`, or retrying after an unreachable server or a 5xx. */
export type Connection = "ok" | "retrying";

export interface RetryPolicy {
  /** first wait (ms), doubled after every failure up to `capMs` */
  firstMs: number;
  capMs: number;
}

const sleep = (ms: number) => new Promise((r) => setTimeout(r, ms));

/** `bytes` random bytes as hex (crypto.getRandomValues works on plain-HTTP pages too, unlike randomUUID). */
function randomHex(bytes: number): string {
  const b = new Uint8Array(bytes);
  crypto.getRandomValues(b);
  return Array.from(b, (x) => x.toString(16).padStart(2, "0")).join("");
}

/** This page load: every event it makes carries it, so that the events of a reloaded page, or of a
 * second tab of the same session, are told apart from this one's. */
const PAGE = randomHex(8);

/** A UI event of this page, now. */
export function uiEvent(type: string, data?: Record<string, unknown>, trial?: number): UIEvent {
  return { t: Date.now(), type, trial, page: PAGE, data };
}

export class Api {
  sessionId = "";
  /** Retries never stop while the page is open: the participant's work is kept until the server answers. */
  retry: RetryPolicy = { firstMs: 300, capMs: 10000 };
  onConnection: (c: Connection, attempt: number) => void = () => undefined;
  private failing = 0; // calls now waiting for the server

  constructor(private token: string) {}

  private async call<T>(method: string, path: string, body?: unknown): Promise<T> {
    let delay = this.retry.firstMs;
    let failed = false;
    for (let attempt = 1; ; attempt++) {
      let res: Response | null = null;
      try {
        res = await fetch(path, {
          method,
          headers: { Authorization: `Bearer ${this.token}`, ...(body ? { "Content-Type": "application/json" } : {}) },
          body: body ? JSON.stringify(body) : undefined,
        });
      } catch {
        res = null;
      }
      if (res === null || res.status >= 500 || res.status === 408 || res.status === 429) {
        if (!failed) this.failing++;
        failed = true;
        this.onConnection("retrying", attempt);
        // a little jitter, so that many pages do not come back in step
        await sleep(delay * (0.8 + 0.4 * Math.random()));
        delay = Math.min(this.retry.capMs, delay * 2);
        continue;
      }
      if (failed && --this.failing === 0) this.onConnection("ok", attempt);
      const data = await res.json().catch(() => ({}));
      if (!res.ok) throw new ApiError(res.status, describeDetail((data as { detail?: unknown }).detail).join("; ") || res.statusText);
      return data as T;
    }
  }

  async me(): Promise<State> {
    // the link holds only the token; the server answers with the session it belongs to
    const st = await this.call<State>("GET", `/api/session`);
    this.sessionId = st.session_id;
    this.resend();
    return st;
  }

  state(): Promise<State> { return this.call("GET", `/api/sessions/${this.sessionId}/state`); }
  consent(events: UIEvent[], panel: Record<string, string> = {}): Promise<State> {
    return this.call("POST", `/api/sessions/${this.sessionId}/consent`, { agree: true, events, panel });
  }
  submitTrial(body: { trial: number; submission_id: string; human_action: "intervene" | "rely"; effort_ms: number | null; events: UIEvent[] }) {
    return this.call<{ trial: TrialResult; duplicate: boolean; state: State }>("POST", `/api/sessions/${this.sessionId}/trials`, body);
  }
  report(after_trial: number, value: number) {
    return this.call<{ state: State }>("POST", `/api/sessions/${this.sessionId}/reports`, { after_trial, value });
  }
  quiz(attempt: number, answers: Record<string, number>) {
    return this.call<{ wrong: string[]; state: State }>("POST", `/api/sessions/${this.sessionId}/quiz`, { attempt, answers });
  }
  answer(questionnaire: string, after_trial: number, answers: Record<string, number>) {
    return this.call<{ state: State }>("POST", `/api/sessions/${this.sessionId}/questionnaires`, { questionnaire, after_trial, answers });
  }
  /** A batch of UI events; its id is made once, so the retries of one batch are stored once.  Until
   * the server answers, the batch is kept in the page's storage (`outbox`): a page reloaded or
   * closed meanwhile sends it again when the session's page opens next (`resend`). */
  events(events: UIEvent[]) {
    const batch = randomHex(16);
    this.outbox((kept) => { kept[batch] = events; });
    return this.send(batch, events);
  }

  private async send(batch: string, events: UIEvent[]) {
    try {
      return await this.call("POST", `/api/sessions/${this.sessionId}/events`, { events, batch });
    } finally {
      this.outbox((kept) => { delete kept[batch]; }); // answered: stored, a repeat, or refused
    }
  }

  private resend() {
    for (const [batch, events] of Object.entries(this.outbox())) this.send(batch, events).catch(() => undefined);
  }

  /** The kept batches of this session (by batch id), changed by `change` when given. */
  private outbox(change?: (kept: Record<string, UIEvent[]>) => void): Record<string, UIEvent[]> {
    const key = `trustseek-outbox-${this.sessionId}`;
    let kept: Record<string, UIEvent[]> = {};
    try {
      kept = JSON.parse(localStorage.getItem(key) ?? "{}") as Record<string, UIEvent[]>;
      if (change) {
        change(kept);
        if (Object.keys(kept).length) localStorage.setItem(key, JSON.stringify(kept));
        else localStorage.removeItem(key);
      }
    } catch {
      // storage unavailable or full: the batch is only retried while this page is open
    }
    return kept;
  }
}
