// The broadcast: the car on the track with its running lap, its laps, the top ten, and the
// winner when the organiser shows it; kept current over the event's websocket.
import { LapClock, laptime, listen } from "./timing.js";

const root = document.querySelector("[data-broadcast]");
const clock = new LapClock(root.querySelector("[data-timer]"));

function item(text, className) {
  const li = document.createElement("li");
  li.textContent = text;
  if (className) li.className = className;
  return li;
}

function showTiming(state) {
  clock.set(state);
  const racer = root.querySelector("[data-racer]");
  const detail = root.querySelector("[data-detail]");
  if (!state.submission) {
    racer.textContent = "Waiting for the next car";
    detail.textContent = "";
    root.querySelector("[data-laps]").replaceChildren();
    return;
  }
  racer.textContent = state.racer;
  const result = state.on_track ? `car ${state.car} · ${state.model_name}`
    : state.qualified ? `finished: ${laptime(state.score_ms)}` : "finished: did not qualify";
  detail.textContent = result;
  root.querySelector("[data-laps]").replaceChildren(...state.laps.map((lap) =>
    item(`${laptime(lap.time_ms)}${lap.off_tracks ? ` (${lap.off_tracks} off)` : ""}`,
      lap.counted ? "" : "not-counted")));
  root.dataset.laps = String(state.laps.length);
}

function showTop(top) {
  root.querySelector("[data-top]").replaceChildren(...top.map((entry) => {
    const li = document.createElement("li");
    const who = document.createElement("span");
    who.textContent = entry.racer;
    if (entry.physical) {
      const real = document.createElement("span");
      real.className = "real";
      real.textContent = " real car";
      who.append(real);
    }
    const time = document.createElement("span");
    time.textContent = laptime(entry.score_ms);
    li.append(who, time);
    return li;
  }));
}

async function refresh() {
  const response = await fetch(root.dataset.stateUrl);
  if (!response.ok) return;
  const state = await response.json();
  showTiming(state.timing);
  showTop(state.top);
}

listen(root.dataset.event, (message) => {
  if (message.type === "timing") showTiming(message);
  if (message.type === "leaderboard" || (message.type === "submission" && message.ranked)) refresh();
  if (message.type === "winner") {
    const winner = root.querySelector("[data-winner]");
    winner.hidden = !message.winner;
    if (message.winner) {
      root.querySelector("[data-winner-racer]").textContent = message.winner.racer;
      root.querySelector("[data-winner-detail]").textContent =
        `${message.winner.model_name} · ${laptime(message.winner.score_ms)}`;
    }
  }
});
refresh();
