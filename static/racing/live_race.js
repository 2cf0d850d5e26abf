// The live race page: the queue follows the event's websocket (the page fetches its queue again
// on each change, and the cars driving too each time the socket opens: updates sent before, or
// while it was closed, reached nobody), and the turn on the track is watched as it drives
// (./turn.js).
import { listen, speedText } from "./timing.js";
import { Turn } from "./turn.js";

const root = document.querySelector("[data-live-race]");
const find = (name) => root.querySelector(`[data-turn-${name}]`);
const turn = new Turn({
  frame: find("frame"), timer: find("timer"), laps: find("laps"),
  speedup: Number(root.dataset.speedup || 1),
});

let last = null; // the turn that drove last: shown until the next one starts
let watched = null; // the car followed: the first of a turn, or the one the viewer chose

const described = (cars, speed = true) => cars.map((car) =>
  `${car.racer} · ${car.model_name}${speed ? ` · ${speedText(car)}` : ""}`).join(" vs ");

function showDriving(queue) {
  const cars = queue.cars || [];
  if (cars.length) last = cars;
  find("racer").textContent = cars.length ? described(cars)
    : last ? `Last turn: ${described(last, false)}` : "Nobody is driving.";
  if (!cars.some((car) => car.evaluation === watched)) watched = cars.length ? cars[0].evaluation : null;
  // a turn of several cars (model against model): the viewer picks the car the video follows
  const choice = find("cars");
  choice.hidden = cars.length < 2;
  choice.replaceChildren(...(cars.length < 2 ? [] : cars).map((car, place) => {
    const button = document.createElement("button");
    button.type = "button";
    button.className = car.evaluation === watched ? "button" : "button button-secondary";
    button.textContent = `Follow car ${place + 1}: ${car.racer}`;
    button.addEventListener("click", () => {
      watched = car.evaluation;
      showDriving(queue);
    });
    return button;
  }));
  root.dataset.driving = watched === null ? "" : String(watched);
  turn.watch(watched);
}

async function refreshQueue() {
  const url = new URL(location.href);
  url.searchParams.set("fragment", "queue");
  const response = await fetch(url, { headers: { "X-Requested-With": "fetch" } });
  if (!response.ok) return;
  const holder = document.createElement("div");
  holder.innerHTML = await response.text();
  root.querySelector("[data-live-queue]").replaceWith(holder.firstElementChild);
  root.dataset.updates = String(Number(root.dataset.updates || 0) + 1);
}

async function catchUp() {
  try {
    const response = await fetch(root.dataset.stateUrl);
    if (!response.ok) return;
    showDriving((await response.json()).queue);
    await refreshQueue();
  } catch {
    // the server is restarting too: the socket's next opening catches up instead
  }
}

listen(root.dataset.event, (message) => {
  if (message.type === "queue") {
    showDriving(message);
    refreshQueue();
  } else if (message.type === "submission") {
    refreshQueue();
  }
}, catchUp);
showDriving(JSON.parse(document.getElementById("live-queue").textContent));
