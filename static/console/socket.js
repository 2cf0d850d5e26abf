// A websocket that comes back: every page's socket to this server. It opens `path` on this host,
// and after each close opens it again, 1 s later, then 2, 4… up to 30 s, from 1 s again once a
// socket has stayed open 10 s (a server that accepts and closes at once, as ours does while Redis
// is down, common/sockets.py, is not retried every second). `onOpen(socket)` runs at every
// opening: where a page catches up on what it missed while closed (fetches its state, watches
// again). `marker`, an element, is marked data-listening "true" while a socket is open and
// "false" once it closes. A close with one of the `refused` codes (the server's no) or a `stop()`
// ends it.
const FIRST_DELAY = 1000; // [ms]
const LAST_DELAY = 30000; // [ms]
const STEADY = 10000; // [ms] open this long, a socket's next close is retried after FIRST_DELAY

export function reconnecting(path, {
  onOpen = () => {}, onMessage = () => {}, onClose = () => {},
  binary = false, refused = [], marker = null,
} = {}) {
  let socket = null;
  let delay = FIRST_DELAY;
  let stopped = false;

  function open() {
    if (stopped) return;
    const scheme = location.protocol === "https:" ? "wss" : "ws";
    const current = new WebSocket(`${scheme}://${location.host}${path}`);
    if (binary) current.binaryType = "arraybuffer";
    let steady = null;
    current.addEventListener("open", () => {
      steady = setTimeout(() => { delay = FIRST_DELAY; }, STEADY);
      if (marker) marker.dataset.listening = "true";
      onOpen(current);
    });
    current.addEventListener("message", (message) => onMessage(message, current));
    current.addEventListener("close", (event) => {
      clearTimeout(steady);
      if (marker) marker.dataset.listening = "false";
      if (stopped) return;
      onClose(event);
      if (refused.includes(event.code)) return;
      setTimeout(open, delay);
      delay = Math.min(delay * 2, LAST_DELAY);
    });
    socket = current;
  }

  open();
  return {
    // `message` as JSON on the socket now open; none is sent while it is closed.
    send(message) {
      if (socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(message));
    },
    stop() {
      stopped = true;
      socket.close();
    },
  };
}
