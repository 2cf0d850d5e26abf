// The event's websocket (reconnecting: ../console/socket.js, its page's body marked
// data-listening while connected), shared by the leaderboard, live race, timekeeper and broadcast
// pages, with onOpen called at each (re)opening for the page to catch up; and a physical event's
// running lap clock, set against this browser's clock by the server's time in each message.
import { reconnecting } from "../console/socket.js";

export function listen(eventId, onMessage, onOpen = () => {}) {
  return reconnecting(`/ws/events/${eventId}/`, {
    marker: document.body,
    onOpen,
    onMessage: (message) => onMessage(JSON.parse(message.data)),
  });
}

export function laptime(milliseconds) {
  if (milliseconds === null || milliseconds === undefined) return "—";
  const total = Math.max(0, Math.round(milliseconds));
  const minutes = Math.floor(total / 60000);
  const seconds = Math.floor((total % 60000) / 1000);
  const millis = total % 1000;
  return `${minutes}:${String(seconds).padStart(2, "0")}.${String(millis).padStart(3, "0")}`;
}

// A lap's off-tracks as every race page words them after its time: " (2 off-tracks)", or nothing.
export function offTracks(count) {
  return count ? ` (${count} off-track${count > 1 ? "s" : ""})` : "";
}

// A live car's speed multiplier and what it makes of its model's top speed (racing.broadcasts's queue).
export function speedText(car) {
  const top = car.top_speed ? `, up to ${car.top_speed.toFixed(1)} m/s${car.capped ? " (the car's limit)" : ""}` : "";
  return `${car.speed.toFixed(1)}× speed${top}`;
}

// The lap on track's time: started at the server's lap_started_ms; the server said server_ms
// when it sent the state, which this browser heard at receivedAt (its own clock).
export class LapClock {
  constructor(element) {
    this.element = element;
    this.started = null;
    this.offset = 0;
    const tick = () => {
      this.element.textContent = this.started === null ? laptime(0) : laptime(this.now() - this.started);
      requestAnimationFrame(tick);
    };
    requestAnimationFrame(tick);
  }
  set(state) {
    this.offset = state.server_ms - Date.now();
    this.started = state.on_track ? state.lap_started_ms : null;
  }
  now() { return Date.now() + this.offset; }
}

// The racer's race time left (the event's race time, from the first crossing: racing.timing),
// counted down against this browser's clock as LapClock counts up. Its holder is shown only while
// a car with a race time is on the track, and marked data-expired once the time is up.
export class RaceClock {
  constructor(holder) {
    this.holder = holder;
    this.left = holder.querySelector("[data-race-left]");
    this.ends = null;
    this.minutes = null;
    this.offset = 0;
    const tick = () => {
      this.show();
      requestAnimationFrame(tick);
    };
    requestAnimationFrame(tick);
  }
  set(state) {
    this.offset = state.server_ms - Date.now();
    this.minutes = state.on_track ? state.race_time_min ?? null : null;
    this.ends = state.race_ends_ms ?? null;
    this.holder.hidden = this.minutes === null;
  }
  show() {
    if (this.minutes === null) return;
    const left = this.ends === null ? this.minutes * 60000 : this.ends - (Date.now() + this.offset);
    const seconds = Math.max(0, Math.ceil(left / 1000));
    this.left.textContent = seconds > 0 ? `${Math.floor(seconds / 60)}:${String(seconds % 60).padStart(2, "0")}` : "time is up";
    this.holder.dataset.expired = String(seconds === 0);
  }
}
