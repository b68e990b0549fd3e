// The participant API (see docs/experiments.md): the session token from the link authorizes
// every call.  Trial submissions carry a client-made submission id, so a retry after a network
// error cannot create a second trial.

export interface Current { trial: number; block: number; block_position: number; practice: boolean; complexity: string; robot_action: "autonomous" | "ask"; scene_seed: number;
  items?: { remaining: Record<string, number>; visible: Record<string, number> | null }; // a block whose policy picks the items
}
export interface Questionnaire {
  name: string; when: "trial" | "block" | "end"; title: string; after_trial: number;
  scale: { min: number; max: number; anchors: string[] }; items: { id: string; text: string }[];
}
export interface State {
  session_id: string; participant: string; status: "new" | "running" | "done"; study: string;
  trials_total: number; trials_done: number; score: number; blocks: string[];
  current: Current | null; report_due: number | null; self_report: "none" | "trial" | "block";
  questionnaire: Questionnaire | null; ended: boolean; completion: { code: string; redirect_url: string | null } | null;
  panel_params: string[]; practice_trials: number;
  animation_speed: number; consent_text: string | null; instructions: string | null;
  rewards: { autonomous_success: number; ask: number; intervene: number; autonomous_failure: number };
}
export interface TrialResult {
  // what the page learns of a committed trial: never the trust belief or the experience
  trial: number; complexity: string; robot_action: string; human_action: string | null; outcome: string;
  reward: number; practice: boolean;
}
export interface UIEvent { t: number; type: string; trial?: number; data?: Record<string, unknown>; }

export class ApiError extends Error {
  constructor(public status: number, message: string) { super(message); }
}

export class Api {
  sessionId = "";
  constructor(private token: string) {}

  private async call<T>(method: string, path: string, body?: unknown, retries = 4): Promise<T> {
    let delay = 300;
    for (let attempt = 0; ; attempt++) {
      let res: Response;
      try {
        res = await fetch(path, {
          method,
          headers: { Authorization: `Bearer ${this.token}`, ...(body ? { "Content-Type": "application/json" } : {}) },
          body: body ? JSON.stringify(body) : undefined,
        });
      } catch (e) {
        if (attempt >= retries) throw new ApiError(0, "the server cannot be reached");
        await new Promise((r) => setTimeout(r, delay));
        delay *= 2;
        continue;
      }
      if (res.status >= 500 && attempt < retries) {
        await new Promise((r) => setTimeout(r, delay));
        delay *= 2;
        continue;
      }
      const data = await res.json().catch(() => ({}));
      if (!res.ok) {
        const d = (data as { detail?: unknown }).detail;
        throw new ApiError(res.status, typeof d === "string" ? d : JSON.stringify(d));
      }
      return data as T;
    }
  }

  async me(): Promise<State> {
    // the link holds only the token; the server answers with the session it belongs to
    const st = await this.call<State>("GET", `/api/session`);
    this.sessionId = st.session_id;
    return st;
  }

  state(): Promise<State> { return this.call("GET", `/api/sessions/${this.sessionId}/state`); }
  consent(events: UIEvent[], panel: Record<string, string> = {}): Promise<State> {
    return this.call("POST", `/api/sessions/${this.sessionId}/consent`, { agree: true, events, panel });
  }
  submitTrial(body: { trial: number; submission_id: string; human_action: "intervene" | "rely"; effort_ms: number | null; events: UIEvent[] }) {
    return this.call<{ trial: TrialResult; duplicate: boolean; state: State }>("POST", `/api/sessions/${this.sessionId}/trials`, body, 8);
  }
  report(after_trial: number, value: number) {
    return this.call<{ state: State }>("POST", `/api/sessions/${this.sessionId}/reports`, { after_trial, value });
  }
  answer(questionnaire: string, after_trial: number, answers: Record<string, number>) {
    return this.call<{ state: State }>("POST", `/api/sessions/${this.sessionId}/questionnaires`, { questionnaire, after_trial, answers });
  }
  events(events: UIEvent[]) { return this.call("POST", `/api/sessions/${this.sessionId}/events`, { events }); }
}
