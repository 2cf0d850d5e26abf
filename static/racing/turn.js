// A live race's turn, as the race and broadcast pages show it: its frames over
// ws/live-turns/<evaluation>/ (each acknowledged once drawn, as the evaluation page's are), its
// laps as they end, and the lap on track's time. Each frame says the simulated time of the lap
// so far (lap_ms). The clock runs at the simulation's pace (speedup times real time) from the
// frame of the last few that came soonest after its render (the largest lap_ms less its
// arrival: a frame that waited on the way would set it back; only the last few, as the
// simulation drifts from real time), never more than a frame and a half past the newest frame's
// word (a simulation that falls behind). At the line it stops on the lap's
// time for a second, as a race's timing screen does, then runs on with the next lap. Its socket
// reconnects (../console/socket.js) and watches again at each opening: the frames resume, and the
// state message the server sends on connecting brings the laps missed meanwhile.
import { reconnecting } from "../console/socket.js";
import { laptime, offTracks } from "./timing.js";

const decoder = new TextDecoder();
const FRAME_MS = 1000 / 15;
const RECENT = 6; // frames the clock is set from: the soonest of the last 0.4 s

export class Turn {
  constructor({ frame, timer, laps, speedup = 1, onLap = () => {} }) {
    Object.assign(this, { frame, timer, laps, speedup, onLap });
    this.socket = null;
    this.evaluation = null;
    this.lapMs = null;
    this.offset = 0;
    this.recent = [];
    this.finished = null;
    this.stoppedUntil = 0;
    this.url = null;
    const tick = () => {
      this.timer.textContent = laptime(this.now());
      requestAnimationFrame(tick);
    };
    requestAnimationFrame(tick);
  }

  now() {
    if (this.evaluation === null && this.finished !== null) return this.finished;
    if (performance.now() < this.stoppedUntil) return this.finished;
    return this.running();
  }

  running() {
    if (this.lapMs === null) return 0;
    return Math.min(performance.now() * this.speedup + this.offset, this.lapMs + 1.5 * FRAME_MS);
  }

  // The turn driving (its evaluation's id), or none: the turn that ended stays shown, its last
  // frame, its laps and its last lap's time, until the next one starts.
  watch(evaluation) {
    if (evaluation === this.evaluation) return;
    this.evaluation = evaluation;
    if (this.socket) this.socket.stop();
    this.socket = null;
    this.lapMs = null;
    if (!evaluation) return;
    this.finished = null;
    this.laps.replaceChildren();
    this.socket = reconnecting(`/ws/live-turns/${evaluation}/`, {
      binary: true,
      onOpen: (socket) => socket.send(JSON.stringify({ type: "watch", worker: 0, view: "spectator" })),
      onMessage: (message, socket) => {
        if (message.data instanceof ArrayBuffer) this.show(socket, message.data);
        else this.receive(JSON.parse(message.data));
      },
    });
  }

  show(socket, data) {
    const length = new DataView(data).getUint32(0);
    const header = JSON.parse(decoder.decode(new Uint8Array(data, 4, length)));
    if (header.lap_ms !== undefined) {
      if (this.lapMs === null || header.lap_ms < this.lapMs) this.recent = []; // a new lap
      this.recent = [...this.recent.slice(1 - RECENT), header.lap_ms - performance.now() * this.speedup];
      this.offset = Math.max(...this.recent);
      this.lapMs = header.lap_ms;
    }
    const url = URL.createObjectURL(new Blob([new Uint8Array(data, 4 + length)], { type: "image/jpeg" }));
    const image = new Image();
    image.src = url;
    image.decode().then(() => {
      const old = this.frame.src;
      this.frame.src = url;
      this.frame.hidden = false;
      this.frame.dataset.frames = String(Number(this.frame.dataset.frames || 0) + 1);
      if (old.startsWith("blob:")) URL.revokeObjectURL(old);
    }).catch(() => URL.revokeObjectURL(url))
      .finally(() => socket.send(JSON.stringify({ type: "ack", seq: header.seq })));
  }

  receive(message) {
    if (message.type === "state") message.history.forEach((row) => this.addLap(row));
    if (message.type === "trial") this.addLap(message);
  }

  addLap(row) {
    if (this.laps.querySelector(`[data-lap="${row.number}"]`)) return;
    const item = document.createElement("li");
    item.dataset.lap = row.number;
    item.value = row.number; // numbered as the lap it is, when earlier ones are left out
    item.textContent = row.status === "lap_complete"
      ? `${laptime(row.time_ms)}${offTracks(row.off_tracks)}` // time_ms holds the penalties
      : `${row.status_display} at ${row.progress.toFixed(0)}%`;
    if (this.lapMs !== null && row.status === "lap_complete") { // a lap ending as it drives
      this.timer.dataset.atLine = laptime(this.running()); // the running clock at the line
      this.stoppedUntil = performance.now() + 1000;
    }
    this.finished = row.time_ms;
    this.laps.append(item);
    this.onLap(row);
  }
}
