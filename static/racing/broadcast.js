// The broadcast: the car on the track (a physical event's run with its running lap, or a live
// race's turn with its video), its laps, the top ten, and the winner when the organiser shows
// it; kept current over the event's websocket, and fetched whole again each time the socket
// opens (updates sent while it was closed reached nobody).
import { LapClock, RaceClock, laptime, listen, offTracks, speedText } from "./timing.js";
import { Turn } from "./turn.js";

const root = document.querySelector("[data-broadcast]");
const physical = root.dataset.physical === "true";
const find = (name) => root.querySelector(`[data-${name}]`);
const clock = physical ? new LapClock(find("timer")) : null;
const raceClock = physical ? new RaceClock(find("race-time")) : null;
const turn = physical ? null : new Turn({
  frame: find("frame"), timer: find("timer"), laps: find("laps"),
  speedup: Number(root.dataset.speedup || 1), onLap: () => fitLaps(),
});

// The newest laps that fit the 16:9 picture: the oldest are left out first (each keeps its
// number), so the list never runs off the bottom of the projector.
function fitLaps() {
  const items = [...find("laps").children];
  items.forEach((li) => { li.hidden = false; });
  for (const li of items.slice(0, -1)) {
    if (root.scrollHeight <= root.clientHeight) break;
    li.hidden = true;
  }
}

function item(text, className, number) {
  const li = document.createElement("li");
  li.textContent = text;
  if (className) li.className = className;
  if (number) li.value = number;
  return li;
}

function showCar(racer, detail) {
  find("racer").textContent = racer || "Waiting for the next car";
  find("detail").textContent = detail || "";
}

function showTiming(state) {
  clock.set(state);
  raceClock.set(state);
  if (!state.submission) {
    showCar();
    find("laps").replaceChildren();
    return;
  }
  showCar(state.racer, state.on_track ? `car ${state.car} · ${state.model_name}`
    : state.qualified ? `finished: ${laptime(state.score_ms)}` : "finished: did not qualify");
  find("laps").replaceChildren(...state.laps.map((lap) =>
    item(`${laptime(lap.time_ms)}${offTracks(lap.off_tracks)}`,
      lap.counted ? "" : "not-counted", lap.number)));
  root.dataset.laps = String(state.laps.length);
  fitLaps();
}

function showQueue(queue) {
  const cars = queue.cars || [];
  showCar(cars.length ? cars.map((car) => car.racer).join(" vs ") : null,
    cars.map((car) => `${car.model_name} · ${speedText(car)}`).join(" vs "));
  turn.watch(cars.length ? cars[0].evaluation : null); // the first car on the grid
}

function showTop(top) {
  find("top").replaceChildren(...top.map((entry) => {
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

// The winner over the whole picture, once the organiser shows it (part of the state a fresh
// broadcast fetches, so a reload keeps it).
function showWinner(winner) {
  find("winner").hidden = !winner;
  if (!winner) return;
  find("winner-racer").textContent = winner.racer;
  find("winner-detail").textContent = `${winner.model_name} · ${laptime(winner.score_ms)}`;
}

async function refresh() {
  let state;
  try {
    const response = await fetch(root.dataset.stateUrl);
    if (!response.ok) return;
    state = await response.json();
  } catch {
    return; // the server is restarting too: the socket's next opening fetches it again
  }
  if (physical) showTiming(state.timing);
  else showQueue(state.queue);
  showTop(state.top);
  showWinner(state.winner);
}

addEventListener("resize", fitLaps);
listen(root.dataset.event, (message) => {
  if (message.type === "timing" && physical) showTiming(message);
  if (message.type === "queue" && !physical) showQueue(message);
  if (message.type === "leaderboard" || (message.type === "submission" && message.ranked)) refresh();
  if (message.type === "winner") showWinner(message.winner);
}, refresh);
refresh();
