// A submission still racing: its status badge follows the race over the event's websocket (the
// one place the page says how far the race is), and the page reloads with the laps and score
// once the submission has ended.
const root = document.querySelector("[data-submission-live]");
const badge = document.querySelector("[data-submission-status]");
const scheme = location.protocol === "https:" ? "wss" : "ws";
const socket = new WebSocket(`${scheme}://${location.host}/ws/events/${root.dataset.event}/`);
socket.addEventListener("open", () => {
  root.dataset.listening = "true";
});
socket.addEventListener("message", (message) => {
  const update = JSON.parse(message.data);
  if (update.type !== "submission" || String(update.submission) !== root.dataset.submission) return;
  badge.textContent = update.status_display;
  badge.className = `badge badge-${update.status.toLowerCase()}`;
  if (["COMPLETED", "FAILED", "CANCELED"].includes(update.status)) location.reload();
});
