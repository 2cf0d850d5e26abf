// The live race page: the queue follows the event's websocket (the page fetches its queue again
// on each change), and the turn on the track is watched as it drives (./turn.js).
import { listen } from "./timing.js";
import { Turn } from "./turn.js";

const root = document.querySelector("[data-live-race]");
const find = (name) => root.querySelector(`[data-turn-${name}]`);
const turn = new Turn({
  frame: find("frame"), timer: find("timer"), laps: find("laps"),
  speedup: Number(root.dataset.speedup || 1),
});

let last = null; // the turn that drove last: shown until the next one starts

function showDriving(queue) {
  const driving = queue.driving;
  if (driving) last = driving;
  find("racer").textContent = driving
    ? `${driving.racer} · ${driving.model_name} · ${driving.speed.toFixed(1)}× speed`
    : last ? `Last turn: ${last.racer} · ${last.model_name}` : "Nobody is driving.";
  root.dataset.driving = driving ? String(driving.evaluation) : "";
  turn.watch(driving ? driving.evaluation : null);
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

listen(root.dataset.event, (message) => {
  if (message.type === "queue") {
    showDriving(message);
    refreshQueue();
  } else if (message.type === "submission") {
    refreshQueue();
  }
});
showDriving(JSON.parse(document.getElementById("live-queue").textContent));
