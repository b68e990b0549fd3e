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

import { ApiError, uiEvent } from "./api";
import { installKeyboard } from "./input";
import { askQuestionnaire, askQuiz, askReport, onQuestionnaire, onQuiz, onReport } from "./participant/forms";
import { $, Phase, api, clearError, fmtReward, forget, log, onConnection, page, save, showError, speedParam, touchOnly } from "./participant/state";
import { setPhase, showFatal } from "./participant/status";
import { frame, intervene, startTrial, useScene } from "./participant/trial";

// --------------------------------------------------------------------------- flow

const TASK_PHASES: Phase[] = ["approach", "reach", "waiting", "outcome", "teleop", "result"];

async function boot() {
  page.route = route;
  if (touchOnly()) {
    showFatal(
      "Please use a computer",
      "Thank you for your interest. This study needs a keyboard (or a gamepad) and a screen of at least 1280 \u00d7 720 pixels: " +
        "please open the same link on a laptop or desktop computer. Nothing has been recorded.",
    );
    return;
  }
  installKeyboard(window, () => TASK_PHASES.includes(page.phase));
  api.onConnection = onConnection;
  window.addEventListener("gamepadconnected", (e) => log("gamepad_connected", { id: (e as GamepadEvent).gamepad.id }));
  window.addEventListener("pagehide", save);
  try {
    page.st = await api.me();
  } catch (e) {
    if (e instanceof ApiError && (e.status === 401 || e.status === 403 || e.status === 404)) {
      showFatal("This link is not valid", "Please check the address you were given, or ask the experimenter for a new link.");
    } else showFatal("The study cannot start", (e as Error).message);
    return;
  }
  page.speed = (page.st.preview && isFinite(speedParam) && speedParam > 0 ? speedParam : 1) * page.st.animation_speed;
  $("preview-tag").hidden = !page.st.preview;
  const practice = page.st.practice_trials;
  const after = practice ? ` (after ${practice} practice trial${practice === 1 ? "" : "s"}, not scored)` : "";
  $("consent-trials").textContent = `${page.st.trials_total - practice} trials${after}`;
  useScene((page.st as { scene?: string }).scene);
  page.shownScore = page.st.score;
  if (page.st.consent_text) $("consent-text").textContent = page.st.consent_text;
  if (page.st.instructions) $("instructions-text").textContent = page.st.instructions;
  const rw = page.st.rewards;
  $("reward-auto").textContent = fmtReward(rw.autonomous_success);
  $("reward-ask").textContent = fmtReward(rw.ask);
  $("reward-int").textContent = fmtReward(rw.intervene);
  $("reward-fail").textContent = fmtReward(rw.autonomous_failure);
  $<HTMLInputElement>("agree").addEventListener("change", (e) => ($<HTMLButtonElement>("consent-btn").disabled = !(e.target as HTMLInputElement).checked));
  $("consent-btn").addEventListener("click", onConsent);
  $("start-btn").addEventListener("click", () => {
    api.events([uiEvent("instructions_done")]).catch(() => undefined);
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
  if (page.st.status === "new") setPhase("consent");
  else route();
}


async function onConsent() {
  $<HTMLButtonElement>("consent-btn").disabled = true;
  // an online panel's ids arrive in the link's query (PROLIFIC_PID, STUDY_ID, SESSION_ID, ...)
  const query = new URLSearchParams(location.search);
  const panel: Record<string, string> = {};
  for (const k of page.st.panel_params) {
    const v = query.get(k);
    if (v) panel[k] = v.slice(0, 200);
  }
  $("consent-status").textContent = "Saving\u2026";
  try {
    page.st = await api.consent([uiEvent("consent")], panel);
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
  page.shownScore = page.st.score;
  if (page.st.ended) return finish();
  if (page.st.quiz) return askQuiz(page.st.quiz);
  if (page.st.report_due !== null) return askReport();
  if (page.st.questionnaire) return askQuestionnaire(page.st.questionnaire);
  if (page.st.current) return startTrial(page.st.current);
  finish();
}

function finish() {
  forget();
  $("final-score").textContent = String(page.st.score);
  $("final-trials").textContent = String(page.st.trials_done - page.st.practice_trials);
  if (page.st.screened) {
    $("done-title").textContent = "Thank you for your time";
    $("done-text").textContent = "The study needs every answer of the check after the instructions right, so it ends here.";
  }
  setPhase("done");
  const c = page.st.completion;
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


boot();
