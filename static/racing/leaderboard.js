// An event's leaderboard, kept current: when a submission is scored (or a ranking changes), the
// event's group says so over the websocket and the page fetches its table again.
const root = document.querySelector("[data-leaderboard]");
const note = root.querySelector("[data-live-note]");
let socket = null;
let retry = 1000;

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  socket = new WebSocket(`${scheme}://${location.host}/ws/events/${root.dataset.event}/`);
  socket.addEventListener("open", () => { retry = 1000; });
  socket.addEventListener("message", (message) => {
    const update = JSON.parse(message.data);
    const own = root.querySelector(`[data-my-submission="${update.submission}"]`);
    if (update.type === "leaderboard" || (update.type === "submission" && (update.ranked || own))) {
      refresh(update);
    }
  });
  socket.addEventListener("close", () => {
    setTimeout(connect, retry);
    retry = Math.min(retry * 2, 30000);
  });
}

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
  note.hidden = false;
  note.textContent = update.type === "submission"
    ? `A new time was just ranked (${new Date().toLocaleTimeString()}).`
    : `The standings changed (${new Date().toLocaleTimeString()}).`;
}

connect();
