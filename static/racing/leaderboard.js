// An event's leaderboard, kept current: when a submission is scored (or a ranking changes), the
// event's group says so over the websocket and the page fetches its table again; and when the
// socket opens again after a close, as what was said meanwhile reached nobody.
import { listen } from "./timing.js";

const root = document.querySelector("[data-leaderboard]");
const note = root.querySelector("[data-live-note]");

async function refresh(update) {
  const url = new URL(location.href);
  url.searchParams.set("fragment", "table");
  url.searchParams.set("page", root.dataset.page);
  const response = await fetch(url, { headers: { "X-Requested-With": "fetch" } });
  if (!response.ok) return;
  const holder = document.createElement("div");
  holder.innerHTML = await response.text();
  root.querySelector("[data-leaderboard-table]").replaceWith(holder.firstElementChild);
  root.dataset.updates = String(Number(root.dataset.updates || 0) + 1);
  if (!update) return;
  note.hidden = false;
  const now = new Date().toLocaleTimeString("en-GB", { hourCycle: "h23" }); // the site's H:i:s
  note.textContent = update.type === "submission"
    ? `A new time was just ranked (${now}).`
    : `The standings changed (${now}).`;
}

let opened = false; // the page was drawn just before the first opening

listen(root.dataset.event, (update) => {
  const own = root.querySelector(`[data-my-submission="${update.submission}"]`);
  if (update.type === "leaderboard" || (update.type === "submission" && (update.ranked || own))) {
    refresh(update);
  }
}, () => {
  if (opened) refresh(null);
  opened = true;
});
