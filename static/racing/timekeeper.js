// The timekeeper's page: one key per signal (racing.timing), the car on the track kept current
// from the answers and from the event's websocket (a timing device may signal too).
import { LapClock, laptime, listen } from "./timing.js";

const root = document.querySelector("[data-timekeeper]");
const onTrack = root.querySelector("[data-on-track]");
const offTrackForm = root.querySelector("[data-off-track-form]");
const error = root.querySelector("[data-error]");
const clock = new LapClock(root.querySelector("[data-timer]"));
const csrf = document.querySelector("[name=csrfmiddlewaretoken]").value;
const KEYS = { " ": "crossing", o: "off_track", r: "reset", u: "undo", f: "finish" };

function show(state) {
  if (state.type !== "timing") return;
  clock.set(state);
  onTrack.hidden = !state.on_track;
  offTrackForm.hidden = state.on_track;
  root.dataset.laps = String(state.laps ? state.laps.length : 0);
  if (!state.on_track) {
    if (state.submission) {
      root.querySelector("[data-last-result]").textContent = state.qualified
        ? `${state.racer}'s run scored ${laptime(state.score_ms)}.`
        : `${state.racer}'s run did not qualify.`;
    }
    return;
  }
  root.querySelector("[data-racer]").textContent = state.racer;
  root.querySelector("[data-car]").textContent = state.car;
  root.querySelector("[data-model]").textContent = state.model_name;
  root.querySelector("[data-lap-number]").textContent = String(state.laps.length + 1);
  root.querySelector("[data-off-tracks]").textContent = String(state.off_tracks);
  root.querySelector("[data-resets]").textContent = String(state.resets);
  root.querySelector("[data-waiting]").hidden = state.lap_started_ms !== null;
  const rows = state.laps.map((lap) => {
    const row = document.createElement("tr");
    for (const [text, numeric] of [[lap.number, true], [laptime(lap.time_ms), true],
      [laptime(lap.penalty_ms), true], [lap.off_tracks, true], [lap.resets, true],
      [lap.counted ? "yes" : "no", false]]) {
      const cell = document.createElement("td");
      cell.textContent = String(text);
      if (numeric) cell.className = "num mono";
      row.append(cell);
    }
    return row;
  });
  root.querySelector("[data-laps]").replaceChildren(...rows);
}

async function send(signal) {
  if (signal === "finish" && !confirm("Finish this run and score its laps?")) return;
  const body = { signal };
  if (signal === "crossing") body.at_ms = Math.round(performance.timeOrigin + performance.now());
  const response = await fetch(root.dataset.signalUrl, {
    method: "POST",
    headers: { "Content-Type": "application/json", "X-CSRFToken": csrf },
    body: JSON.stringify(body),
  });
  const answer = await response.json();
  error.textContent = response.ok ? "" : answer.error;
  if (response.ok) show(answer);
}

document.addEventListener("keydown", (key) => {
  if (onTrack.hidden || key.target.closest("input, textarea, select") || key.repeat) return;
  const signal = KEYS[key.key.toLowerCase()];
  if (!signal) return;
  key.preventDefault();
  send(signal);
});
root.querySelectorAll("[data-send]").forEach((button) => {
  button.addEventListener("click", () => send(button.dataset.send));
});
show(JSON.parse(document.getElementById("timing-state").textContent));
listen(root.dataset.event, show);
