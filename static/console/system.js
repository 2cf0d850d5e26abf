// The System page's worker probe: one websocket (reconnecting: ./socket.js), a button that asks
// for a probe while it is open, a line per answer.
import { reconnecting } from "./socket.js";

const PROBE_TIMEOUT_MS = 10000;

const section = document.querySelector("[data-probe-url]");
const button = section.querySelector("[data-probe-button]");
const log = section.querySelector("[data-probe-log]");
const pending = new Map();

function line(queue, ok, text) {
  const item = document.createElement("li");
  item.dataset.queue = queue;
  item.dataset.ok = ok;
  const name = document.createElement("strong");
  name.textContent = queue;
  const badge = document.createElement("span");
  badge.className = `badge badge-${ok ? "ok" : "down"}`;
  badge.textContent = ok ? "answered" : "no answer";
  const detail = document.createElement("span");
  detail.textContent = text;
  item.append(name, badge, detail);
  log.append(item);
}

function receive(event) {
  const message = JSON.parse(event.data);
  if (message.type === "probe.sent") {
    for (const queue of message.queues) {
      pending.set(queue, setTimeout(() => {
        pending.delete(queue);
        line(queue, false, `No worker took the task within ${PROBE_TIMEOUT_MS / 1000} s: start one with -Q ${queue}.`);
      }, PROBE_TIMEOUT_MS));
    }
  } else if (message.type === "probe.result") {
    clearTimeout(pending.get(message.queue));
    pending.delete(message.queue);
    line(message.queue, true, `${message.worker} (pid ${message.pid}) took it after ${message.waited_ms} ms`);
  } else if (message.type === "error") {
    line("probe", false, message.message);
  }
}

const socket = reconnecting(section.dataset.probeUrl, {
  onOpen: () => { button.disabled = false; },
  onMessage: receive,
  onClose: () => {
    if (button.disabled) return; // it was not open: said already
    button.disabled = true;
    line("websocket", false, "The connection to the server closed; reconnecting…");
  },
});

button.addEventListener("click", () => {
  log.replaceChildren();
  socket.send({ action: "probe" });
});
