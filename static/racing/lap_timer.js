// DREM's lap timer on the timekeeper's page: the DeepRacer Event Manager's Raspberry Pi serves
// its light gates' crossings over a websocket (leaderboard-timer/timer.js), as DREM's own
// timekeeper page listens to them; this page listens the same way and passes each message on,
// as it came, to the event's signal endpoint (racing.timing_signals.DREM_EVENTS reads it). The address
// is kept in this browser for the next race night.
const KEPT = "pitlane.lapTimer";
const AGAIN_MS = 5000; // DREM's page tries again 5 s after a close, as this one does

export function relayLapTimer(panel, post) {
  const form = panel.querySelector("[data-lap-timer-form]");
  const address = panel.querySelector("[data-lap-timer-address]");
  const stop = panel.querySelector("[data-lap-timer-stop]");
  const status = panel.querySelector("[data-lap-timer-status]");
  let socket = null;
  let again = null;
  address.value = localStorage.getItem(KEPT) || "";

  function listen(url) {
    clearTimeout(again);
    socket = new WebSocket(url);
    socket.addEventListener("open", () => {
      status.textContent = `Listening to the lap timer at ${url}: each lap it sees is a crossing.`;
      panel.dataset.listening = "true";
    });
    socket.addEventListener("message", (message) => post(String(message.data)));
    socket.addEventListener("close", () => {
      panel.dataset.listening = "false";
      if (socket === null) return; // stopped on purpose
      status.textContent = `The lap timer at ${url} does not answer: trying again every 5 s.`;
      again = setTimeout(() => listen(url), AGAIN_MS);
    });
  }

  form.addEventListener("submit", (submitted) => {
    submitted.preventDefault();
    const url = address.value.trim();
    if (!/^wss?:\/\/[^\s/]+/.test(url)) {
      status.textContent = "Give the timer's address as DREM prints it: ws://<its IP>:8080.";
      return;
    }
    if (location.protocol === "https:" && url.startsWith("ws://")) {
      status.textContent = "A page served over https may not listen to ws://: give the timer's "
        + "wss:// address, or open the console over http on the club's network.";
      return;
    }
    localStorage.setItem(KEPT, url);
    const old = socket;
    socket = null;
    old?.close();
    stop.hidden = false;
    status.textContent = `Connecting to ${url}…`;
    listen(url);
  });
  stop.addEventListener("click", () => {
    clearTimeout(again);
    const old = socket;
    socket = null;
    old?.close();
    stop.hidden = true;
    status.textContent = "Not listening to a lap timer.";
  });
}
