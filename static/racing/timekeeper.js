// The timekeeper's page: one key per signal (racing.timing), the car on the track kept current
// from the answers and from the event's websocket (a timing device may signal too); each lap
// struck out or restored from its row (racing.lap_edits); racers searched by racer name as the
// timekeeper types, never by login name; the device token copied with one press; DREM's lap
// timer listened to (lap_timer.js).
import { relayLapTimer } from "./lap_timer.js";
import { LapClock, RaceClock, laptime, listen } from "./timing.js";

const root = document.querySelector("[data-timekeeper]");
const onTrack = root.querySelector("[data-on-track]");
const offTrackForm = root.querySelector("[data-off-track-form]");
const error = root.querySelector("[data-error]");
const clock = new LapClock(root.querySelector("[data-timer]"));
const raceClock = new RaceClock(root.querySelector("[data-race-time]"));
const csrf = document.querySelector("[name=csrfmiddlewaretoken]").value;
const KEYS = { " ": "crossing", o: "off_track", r: "reset", u: "undo", f: "finish" };
const runUrl = (submission) => root.dataset.runUrl.replace(/\/0\/$/, `/${submission}/`);
let shown = null; // the last state shown

function counts(lap) {
  if (lap.struck) return "no: struck out";
  if (!lap.counted) return "no";
  return lap.far_below ? "yes · far below the others: a double press? Strike it out if so" : "yes";
}

function lapRow(lap) {
  const row = document.createElement("tr");
  if (lap.struck) row.className = "struck";
  else if (lap.far_below) row.className = "far-below";
  for (const [text, numeric] of [[lap.number, true], [laptime(lap.time_ms), true],
    [laptime(lap.penalty_ms), true], [lap.off_tracks, true], [lap.resets, true],
    [counts(lap), false]]) {
    const cell = document.createElement("td");
    cell.textContent = String(text);
    if (numeric) cell.className = "num mono";
    row.append(cell);
  }
  const edit = document.createElement("button");
  edit.type = "button";
  edit.className = lap.struck ? "button button-secondary" : "button button-danger";
  edit.textContent = lap.struck ? `Restore lap ${lap.number}` : `Strike lap ${lap.number} out`;
  edit.addEventListener("click", () => editLap(lap.struck ? "restore" : "strike", lap.number));
  const cell = document.createElement("td");
  cell.append(edit);
  row.append(cell);
  return row;
}

function showResult(state) {
  const result = root.querySelector("[data-last-result]");
  if (!state.submission) return;
  const shownFor = `${state.submission} ${state.verdict}`;
  // The same result comes twice (the signal's answer, then the event's websocket): the link a
  // timekeeper may have focused stays.
  if (result.dataset.shownFor === shownFor) return;
  result.dataset.shownFor = shownFor;
  const link = document.createElement("a");
  link.href = runUrl(state.submission);
  link.textContent = "Edit this run's laps";
  result.replaceChildren(`${state.verdict} `, link);
}

function show(state) {
  if (state.type !== "timing") return;
  shown = state;
  clock.set(state);
  raceClock.set(state);
  onTrack.hidden = !state.on_track;
  offTrackForm.hidden = state.on_track;
  root.dataset.laps = String(state.laps ? state.laps.length : 0);
  if (!state.on_track) {
    showResult(state);
    return;
  }
  root.querySelector("[data-racer]").textContent = state.racer;
  root.querySelector("[data-car]").textContent = state.car;
  root.querySelector("[data-model]").textContent = state.model_name;
  root.querySelector("[data-lap-number]").textContent = String(state.laps.length + 1);
  root.querySelector("[data-off-tracks]").textContent = String(state.off_tracks);
  root.querySelector("[data-resets]").textContent = String(state.resets);
  root.querySelector("[data-waiting]").hidden = state.lap_started_ms !== null;
  root.querySelector("[data-run-link]").href = runUrl(state.submission);
  root.querySelector("[data-laps]").replaceChildren(...state.laps.map(lapRow));
}

async function answered(response) {
  const answer = await response.json().catch(() => ({ error: "The console did not answer: try again." }));
  error.textContent = response.ok ? "" : answer.error;
  if (response.ok) show(answer);
}

// A signal's JSON, a key's or a lap timer's as it came (racing.timing_signals reads DREM's events).
async function post(body) {
  await answered(await fetch(root.dataset.signalUrl, {
    method: "POST",
    headers: { "Content-Type": "application/json", "X-CSRFToken": csrf },
    body,
  }));
}
relayLapTimer(document.querySelector("[data-lap-timer]"), post);

async function send(signal) {
  if (signal === "finish" && !confirm("Finish this run and score its laps?")) return;
  const body = { signal };
  if (signal === "crossing") body.at_ms = Math.round(performance.timeOrigin + performance.now());
  await post(JSON.stringify(body));
}

async function editLap(action, number) {
  if (!shown || !shown.submission) return;
  const body = new FormData();
  body.append("action", action);
  body.append("lap", String(number));
  await answered(await fetch(`${runUrl(shown.submission)}laps`, {
    method: "POST",
    headers: { Accept: "application/json", "X-CSRFToken": csrf },
    body,
  }));
}

// Space is always a crossing, even with a button focused (Enter presses a focused button).
document.addEventListener("keydown", (key) => {
  if (onTrack.hidden || key.target.closest("input, textarea, select") || key.repeat) return;
  const signal = KEYS[key.key.toLowerCase()];
  if (!signal) return;
  key.preventDefault();
  send(signal);
});
document.addEventListener("keyup", (key) => {
  if (!onTrack.hidden && key.key === " " && key.target.closest("button")) key.preventDefault();
});
root.querySelectorAll("[data-send]").forEach((button) => {
  button.addEventListener("click", () => send(button.dataset.send));
});

// The racer search: the racer names that match what is typed, as buttons under the field (Tab
// reaches them); pressing one puts the name in the field.
const search = root.querySelector("[data-racer-search]");
const suggestions = root.querySelector("[data-racer-suggestions]");
let typing = null;

function suggest(racers) {
  suggestions.replaceChildren(...racers.map((name) => {
    const button = document.createElement("button");
    button.type = "button";
    button.className = "button button-secondary button-small";
    button.textContent = name;
    button.addEventListener("click", () => {
      search.value = name;
      suggestions.replaceChildren();
      search.focus();
    });
    return button;
  }));
}

let searches = 0;
search?.addEventListener("input", () => {
  clearTimeout(typing);
  typing = setTimeout(async () => {
    const text = search.value.trim();
    if (!text) return suggest([]);
    const asked = ++searches; // a slower answer to an older search must not overwrite this one
    const response = await fetch(`${root.dataset.racersUrl}?q=${encodeURIComponent(text)}`);
    const json = (response.headers.get("Content-Type") || "").includes("json");
    if (asked === searches && response.ok && json) suggest((await response.json()).racers);
  }, 150);
});

const copy = document.querySelector("[data-copy-token]");
copy?.addEventListener("click", async () => {
  const token = document.querySelector("[data-device-token]").textContent;
  const said = document.querySelector("[data-copied]");
  try {
    await navigator.clipboard.writeText(token);
    said.textContent = "Copied.";
  } catch {
    getSelection().selectAllChildren(document.querySelector("[data-device-token]"));
    said.textContent = "Selected: press Ctrl+C to copy it.";
  }
});

// The car on the track as this page's server draws it now: after the socket opens again, since a
// device's signals while it was closed reached nobody.
async function catchUp() {
  try {
    const response = await fetch(location.href, { headers: { Accept: "text/html" } });
    if (!response.ok) return;
    const page = new DOMParser().parseFromString(await response.text(), "text/html");
    const state = page.getElementById("timing-state");
    if (state) show(JSON.parse(state.textContent));
  } catch {
    // the server is restarting too: the socket's next opening catches up instead
  }
}

let opened = false; // the page was drawn just before the first opening

show(JSON.parse(document.getElementById("timing-state").textContent));
listen(root.dataset.event, show, () => {
  if (opened) catchUp();
  opened = true;
});
