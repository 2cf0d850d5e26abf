// A submission still racing: its status badge follows the race over the event's websocket (the
// one place the page says how far the race is), and the page reloads with the laps and score
// once the submission has ended. The socket reconnects (../console/socket.js), and the status is
// read again at each opening.
import { reconnecting } from "../console/socket.js";

const root = document.querySelector("[data-submission-live]");
const badge = document.querySelector("[data-submission-status]");
const ENDED = ["COMPLETED", "FAILED", "CANCELED"];

function show(status, display) {
  badge.textContent = display;
  badge.className = `badge badge-${status.toLowerCase()}`;
  if (ENDED.includes(status)) location.reload();
}

let updated = false; // a socket update has been shown since the socket opened: newer than a fetch

// The race may have moved on between this page being drawn (or the socket closing) and the
// socket opening (its updates went to nobody): read the status once more, now that no update
// can be missed.
async function catchUp() {
  updated = false;
  try {
    const response = await fetch(location.href, { headers: { Accept: "text/html" } });
    if (!response.ok) return;
    const page = new DOMParser().parseFromString(await response.text(), "text/html");
    const now = page.querySelector("[data-submission-status]");
    const status = now?.dataset.submissionStatus;
    if (status && !updated) show(status, now.textContent);
  } catch {
    // The socket's next update says it instead.
  } finally {
    root.dataset.listening = "true";
  }
}

reconnecting(`/ws/events/${root.dataset.event}/`, {
  onOpen: catchUp,
  onClose: () => { root.dataset.listening = "false"; },
  onMessage: (message) => {
    const update = JSON.parse(message.data);
    if (update.type !== "submission" || String(update.submission) !== root.dataset.submission) return;
    updated = true;
    show(update.status, update.status_display);
  },
});
