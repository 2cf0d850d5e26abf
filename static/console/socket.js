// A websocket that comes back: every page's socket to this server. It opens `path` on this host,
// and after each close opens it again, 1 s later, then 2, 4… up to 30 s (from 1 s again once a
// socket has opened, unless the server closed it to say "try again later": 4503, a Redis outage,
// common/sockets.py). `onOpen(socket)` runs at every opening: where a page catches up on what it
// missed while closed (fetches its state, watches again). `marker`, an element, is marked
// data-listening "true" while a socket is open and "false" once it closes. A close with one of
// the `refused` codes (the server's no) or a `stop()` ends it.
export const TRY_AGAIN_LATER = 4503;
const FIRST_DELAY = 1000; // [ms]
const LAST_DELAY = 30000; // [ms]

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
    let opened = false;
    current.addEventListener("open", () => {
      opened = true;
      if (marker) marker.dataset.listening = "true";
      onOpen(current);
    });
    current.addEventListener("message", (message) => onMessage(message, current));
    current.addEventListener("close", (event) => {
      if (marker) marker.dataset.listening = "false";
      if (stopped) return;
      onClose(event);
      if (refused.includes(event.code)) return;
      if (opened && event.code !== TRY_AGAIN_LATER) delay = FIRST_DELAY;
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
