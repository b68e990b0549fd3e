// The participant page's forms: the self-report of trust, the comprehension quiz and the
// questionnaires; each answer goes to the server, then the study's next screen.

import { Questionnaire, Quiz } from "../api";
import { $, api, clearError, page, showError } from "./state";
import { setPhase } from "./status";

export function askReport() {
  $<HTMLInputElement>("report-slider").value = "50";
  $("report-value").textContent = "\u2013";
  $<HTMLButtonElement>("report-btn").disabled = true;
  $("report-scope").textContent = page.st.self_report === "block" ? "this block" : "this trial";
  setPhase("report");
}

export async function onReport() {
  const v = Number($<HTMLInputElement>("report-slider").value);
  $<HTMLButtonElement>("report-btn").disabled = true;
  try {
    const res = await api.report(page.st.report_due!, v);
    page.st = res.state;
  } catch (e) {
    $<HTMLButtonElement>("report-btn").disabled = false;
    showError(`Could not save your answer: ${(e as Error).message}. Please try again.`);
    return;
  }
  clearError();
  page.route();
}

// --------------------------------------------------------------------------- the comprehension quiz

export function askQuiz(q: Quiz) {
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
  $<HTMLButtonElement>("quiz-btn").disabled = Object.keys(quizAnswers()).length < (page.st.quiz?.questions.length ?? 0);
}

export async function onQuiz() {
  const q = page.st.quiz!;
  $<HTMLButtonElement>("quiz-btn").disabled = true;
  try {
    const res = await api.quiz(q.attempt, quizAnswers());
    page.st = res.state;
  } catch (e) {
    updateQuizButton();
    showError(`Could not save your answers: ${(e as Error).message}. Please try again.`);
    return;
  }
  clearError();
  // a wrong answer with attempts left: the instructions again, then the quiz
  if (page.st.quiz) {
    setPhase("instructions");
    $("instructions-again").hidden = false;
    return;
  }
  page.route();
}

let asked: Questionnaire | null = null;

export function askQuestionnaire(q: Questionnaire) {
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

export async function onQuestionnaire() {
  const q = asked!;
  $<HTMLButtonElement>("questionnaire-btn").disabled = true;
  try {
    const res = await api.answer(q.name, q.after_trial, questionnaireAnswers());
    page.st = res.state;
  } catch (e) {
    updateQuestionnaireButton();
    showError(`Could not save your answers: ${(e as Error).message}. Please try again.`);
    return;
  }
  clearError();
  page.route();
}
