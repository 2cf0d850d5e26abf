// A submission still racing: reload the page once its event says the submission has ended.
const root = document.querySelector("[data-submission-live]");
const scheme = location.protocol === "https:" ? "wss" : "ws";
const socket = new WebSocket(`${scheme}://${location.host}/ws/events/${root.dataset.event}/`);
socket.addEventListener("message", (message) => {
  const update = JSON.parse(message.data);
  if (update.type !== "submission" || String(update.submission) !== root.dataset.submission) return;
  document.querySelector("[data-submission-status]").textContent = update.status_display;
  if (["COMPLETED", "FAILED", "CANCELED"].includes(update.status)) location.reload();
});
