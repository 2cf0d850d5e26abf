// A live job on the page: its video, its status and its graph (training) or results (evaluation),
// over one websocket. Frames come as binary messages: a 4-byte length, a JSON header, the JPEG.
// Each drawn frame is acknowledged, and the server sends the next one only then: a slow page
// gets the newest frame, never a backlog. The socket reconnects with backoff
// (../console/socket.js), and the server sends the whole state on connecting, so a page that
// reconnects is up to date at once; it watches again what it watched.
import { reconnecting } from "../console/socket.js";

const section = document.querySelector("[data-live-url]");
const kind = section.dataset.liveKind;
const find = (name) => document.querySelector(`[data-live-${name}]`);
const frame = find("frame");
const overlay = find("overlay");
const rate = find("rate");
const decoder = new TextDecoder();
const REFUSED = new Set([4401, 4403]);

let socket = null;
let state = null;
let frameUrl = null;
let framesShown = 0;
let frameTimes = [];

function laptime(milliseconds) {
  if (milliseconds === null || milliseconds === undefined) return "—";
  const total = Math.round(milliseconds);
  const minutes = Math.floor(total / 60000);
  const seconds = Math.floor((total % 60000) / 1000);
  const millis = total % 1000;
  return `${minutes}:${String(seconds).padStart(2, "0")}.${String(millis).padStart(3, "0")}`;
}

function clock(seconds) {
  const whole = Math.max(0, Math.round(seconds));
  return `${Math.floor(whole / 60)}:${String(whole % 60).padStart(2, "0")}`;
}

// The connection

function connect() {
  socket = reconnecting(section.dataset.liveUrl, {
    binary: true,
    refused: [...REFUSED],
    onOpen: watch,
    onMessage: (event) => {
      if (event.data instanceof ArrayBuffer) showFrame(event.data);
      else receive(JSON.parse(event.data));
    },
    onClose: (event) => {
      if (REFUSED.has(event.code)) say("You may not watch this job.");
      else if (state && !state.active) socket.stop(); // a job that ended sends nothing more
      else say("The connection was lost; reconnecting…");
    },
  });
}

function send(message) {
  socket?.send(message);
}

function watch() {
  const worker = find("worker");
  send({
    type: "watch",
    view: find("view")?.value ?? "spectator",
    worker: worker ? Number(worker.value) : 0,
  });
}

// The view chosen is remembered per model, for the next visit and the next reload.
const viewChoice = find("view");
const viewKey = viewChoice?.dataset.remember;
if (viewChoice && viewKey) {
  const kept = window.localStorage.getItem(viewKey);
  if ([...viewChoice.options].some((option) => option.value === kept)) viewChoice.value = kept;
}
viewChoice?.addEventListener("change", () => {
  if (viewKey) window.localStorage.setItem(viewKey, viewChoice.value);
  watch();
});
find("worker")?.addEventListener("change", watch);

function say(text) {
  if (!overlay) return;
  overlay.textContent = text;
  overlay.hidden = !text;
}

// Frames

function showFrame(data) {
  const length = new DataView(data).getUint32(0);
  const header = JSON.parse(decoder.decode(new Uint8Array(data, 4, length)));
  const url = URL.createObjectURL(new Blob([new Uint8Array(data, 4 + length)], { type: "image/jpeg" }));
  const image = new Image();
  image.src = url;
  image.decode().then(() => {
    if (!frame) return;
    frame.src = url;
    frame.hidden = false;
    frame.dataset.view = header.view;
    frame.dataset.seq = header.seq;
    frame.dataset.paused = Boolean(header.paused);
    frame.dataset.moment = `${header.episode}:${header.step}`;
    frame.dataset.frames = ++framesShown;
    if (frameUrl) URL.revokeObjectURL(frameUrl);
    frameUrl = url;
    const now = performance.now();
    frameTimes = frameTimes.filter((time) => now - time < 1000);
    frameTimes.push(now);
    if (rate) rate.textContent = header.paused ? "paused" : `${frameTimes.length} frames/s`;
    if (header.paused) say("The car waits while the policy is updated.");
    else if (state && state.active) say("");
  }).catch(() => URL.revokeObjectURL(url)).finally(() => send({ type: "ack", seq: header.seq }));
}

// Messages

function receive(message) {
  // The model page's log reads its new lines again (static/training/log.js).
  document.dispatchEvent(new CustomEvent("pitlane:job-update", { detail: message.type }));
  if (message.type === "state") {
    setStatus(message);
    for (const row of message.history) (kind === "training" ? addIteration : addTrial)(row);
    if (kind === "training") {
      drawChart();
      showTimeSplit();
    }
  } else if (message.type === "status") {
    setStatus(message);
  } else if (message.type === "iteration") {
    addIteration(message);
    drawChart();
    showTimeSplit();
  } else if (message.type === "trial") {
    addTrial(message);
  }
}

let leaving = false; // a form was sent (Stop evaluation): its answer replaces the page
document.addEventListener("submit", () => { leaving = true; });

function setStatus(message) {
  const wasActive = state ? state.active : null;
  state = message;
  section.dataset.jobStatus = message.status;
  let text = message.status_display;
  if (message.queue_words) text += `: ${message.queue_words}`;
  if (message.message) text += ` · ${message.message}`;
  find("status").textContent = text;
  const failure = find("failure");
  if (failure) {
    failure.hidden = !message.failure_reason;
    failure.querySelector("dd").textContent = message.failure_reason;
  }
  const badge = find("model-status");
  if (badge && message.model_status_display) badge.textContent = message.model_status_display;
  for (const element of document.querySelectorAll("[data-live-when-active]")) element.hidden = !message.active;
  if (message.model_status) {
    for (const element of document.querySelectorAll("[data-live-when-model]")) {
      element.hidden = !element.dataset.liveWhenModel.split(" ").includes(message.model_status);
    }
  }
  if (message.seconds_used !== undefined) {
    clockOrigin = {
      seconds: message.seconds_used, at: performance.now(), running: message.clock_running,
      max: message.max_seconds, active: message.active && message.status !== "STOPPING",
    };
  }
  const stopper = document.querySelector("[data-stop-open]"); // hidden once the stop is asked
  if (stopper) stopper.hidden = !message.active || message.status === "STOPPING";
  const finished = document.querySelector("[data-stop-iteration]");
  if (finished && message.iterations) finished.textContent = `iteration ${message.iterations}`;
  const progress = find("progress");
  if (progress && message.iterations !== undefined) {
    progress.textContent = `${message.iterations} iteration${message.iterations === 1 ? "" : "s"}, `
      + `${message.episodes} episode${message.episodes === 1 ? "" : "s"}, ${message.steps} steps`;
  }
  if (!message.active) {
    if (kind === "training") showTimeSplit(); // its evaluation no longer comes
    say(message.status === "COMPLETED" ? "Finished: no more live video." : `${message.status_display}.`);
    const ended = message.status === "COMPLETED" || message.status === "CANCELED"; // a video to show
    if (kind === "evaluation" && wasActive && ended && !leaving) window.location.reload();
  } else if (message.status === "QUEUED" || message.status === "INITIALIZING") {
    say("The simulation starts when a worker takes the job.");
  }
  tick();
}

// The training clock counts from the server's word: the time used (seconds_used) when the
// server said it, counted on with the page's monotonic clock from the moment the word came (the
// page's response, then each status message), never from the page's own idea of the time. So
// the page, every other tab and the model list agree, and nothing jumps when a message comes.

let clockOrigin = null; // {seconds, at (performance.now() when said), running, max, active}
let clockShown = 0;

function clockFromPage() {
  const time = find("time");
  if (!time || time.dataset.secondsUsed === undefined) return;
  const response = performance.getEntriesByType("navigation")[0]?.responseStart;
  clockOrigin = {
    seconds: Number(time.dataset.secondsUsed), at: response || performance.now(),
    running: time.dataset.clockRunning === "true", max: Number(time.dataset.maxSeconds),
    active: time.dataset.active === "true",
  };
}

function tick() {
  const time = find("time");
  if (!time || !clockOrigin) return;
  const { seconds, at, running, max, active } = clockOrigin;
  let used = Math.min(seconds + (running ? (performance.now() - at) / 1000 : 0), max);
  if (running) used = Math.max(used, clockShown); // a fresher word never turns it back
  clockShown = used;
  time.dataset.shownSeconds = used.toFixed(1);
  time.textContent = `${clock(used)} used of ${max / 60} min` + (active ? ` · ${clock(max - used)} left` : "");
  for (const element of document.querySelectorAll("[data-stop-time]")) element.textContent = clock(used);
}

clockFromPage();
tick();
setInterval(tick, 1000);

// Training: the graph and the iteration table

const iterations = new Map();
const chartCanvas = find("chart");
let chart = null;

function addIteration(row) {
  iterations.set(row.number, row);
  const body = find("iterations");
  if (!body) return;
  find("iteration-table").hidden = false;
  find("no-iterations").hidden = true;
  const cells = [
    row.number, row.reward.toFixed(2), `${row.completion.toFixed(1)}%`,
    row.evaluation_completion === null ? "—" : `${row.evaluation_completion.toFixed(1)}%`,
    laptime(row.best_lap_time === null ? null : row.best_lap_time * 1000),
    row.episodes, row.steps,
  ];
  let line = body.querySelector(`tr[data-number="${row.number}"]`);
  if (!line) {
    line = document.createElement("tr");
    line.dataset.number = row.number;
    for (let i = 0; i < 7; i++) line.append(Object.assign(document.createElement("td"), { className: "num" }));
    body.prepend(line);
  }
  cells.forEach((value, index) => { line.children[index].textContent = value; });
}

// Where the newest iteration's time went (the same as the page's template draws it).
function showTimeSplit() {
  const panel = find("time-split");
  const newest = Math.max(...iterations.keys());
  const row = iterations.get(newest);
  if (!panel || !row || !row.time_split || !row.time_split.length) return;
  panel.hidden = false;
  panel.querySelector("[data-split-number]").textContent = row.number;
  panel.querySelector("[data-split-wall]").textContent = row.wall_seconds.toFixed(1);
  const bar = panel.querySelector("[data-split-bar]");
  const legend = panel.querySelector("[data-split-legend]");
  bar.replaceChildren(...row.time_split.map((part) => {
    const piece = document.createElement("span");
    piece.className = `split-${part.phase}`;
    piece.style.width = `${part.share}%`;
    return piece;
  }));
  legend.replaceChildren(...row.time_split.map((part) => {
    const item = document.createElement("li");
    item.dataset.phase = part.phase;
    const key = Object.assign(document.createElement("span"), { className: `split-key split-${part.phase}` });
    const figures = Object.assign(document.createElement("span"), {
      className: "num", textContent: `${part.seconds.toFixed(1)} s · ${Math.round(part.share)}%`,
    });
    item.append(key, `${part.label} `, figures);
    return item;
  }));
  const ended = state && !state.active;
  panel.querySelector("[data-split-evaluation]").textContent = row.evaluation_seconds !== null
    ? `Its evaluation drove ${row.evaluation_seconds.toFixed(1)} s beside the next iteration.`
    : ended ? "Training ended before its evaluation finished." : "Its evaluation drives beside the next iteration.";
}

// The completion axis ends at 100%, and points there are drawn whole (clip: false), not cut
// in half by the chart's edge. On a narrow screen the legend goes under the graph, in short
// words and small marks, so that the graph keeps its height.
const NARROW = 560; // [px] of chart width

function legendFor(width) {
  const narrow = width < NARROW;
  return {
    position: narrow ? "bottom" : "top",
    labels: {
      usePointStyle: true,
      boxWidth: narrow ? 7 : 10,
      boxHeight: narrow ? 7 : 10,
      padding: narrow ? 6 : 10,
      font: { size: narrow ? 10 : 12 },
      generateLabels: (current) => window.Chart.defaults.plugins.legend.labels.generateLabels(current)
        .map((item) => ({ ...item, text: current.data.datasets[item.datasetIndex][narrow ? "short" : "label"] })),
    },
  };
}

function drawChart() {
  if (!chartCanvas || !window.Chart) return;
  const rows = [...iterations.values()].sort((a, b) => a.number - b.number);
  const line = (key) => rows.filter((row) => row[key] !== null).map((row) => ({ x: row.number, y: row[key] }));
  const points = (pick) => rows.flatMap((row) => pick(row).map((y) => ({ x: row.number, y })));
  const averages = { type: "line", clip: false, borderWidth: 2, pointRadius: 3, pointHoverRadius: 5 };
  const dots = { type: "scatter", clip: false, pointRadius: 3.5, pointHoverRadius: 5, pointBorderWidth: 1 };
  const datasets = [
    { ...averages, label: "Average reward (training)", short: "Reward", data: line("reward"), yAxisID: "reward", borderColor: "#0969da", backgroundColor: "#0969da" },
    { ...averages, label: "Average completion (training)", short: "Completion", data: line("completion"), yAxisID: "completion", borderColor: "#1a7f37", backgroundColor: "#1a7f37" },
    { ...averages, label: "Average completion (evaluation)", short: "Evaluation", data: line("evaluation_completion"), yAxisID: "completion", borderColor: "#cf222e", backgroundColor: "#cf222e" },
    { ...dots, label: "Reward per episode", short: "Reward, episode", data: points((row) => row.training_points.map((p) => p[0])), yAxisID: "reward", backgroundColor: "rgb(9 105 218 / 0.45)", borderColor: "#0550ae" },
    { ...dots, label: "Completion per episode (training)", short: "Completion, episode", data: points((row) => row.training_points.map((p) => p[1])), yAxisID: "completion", backgroundColor: "rgb(26 127 55 / 0.45)", borderColor: "#116329", pointStyle: "rect" },
    { ...dots, label: "Completion per episode (evaluation)", short: "Evaluation, episode", data: points((row) => row.evaluation_points), yAxisID: "completion", backgroundColor: "rgb(207 34 46 / 0.5)", borderColor: "#a40e26", pointStyle: "triangle" },
  ];
  chartCanvas.dataset.iterations = rows.length;
  chartCanvas.dataset.points = datasets.reduce((sum, set) => sum + set.data.length, 0);
  if (chart) {
    chart.data.datasets.forEach((set, index) => { set.data = datasets[index].data; });
    chart.update("none");
    return;
  }
  chart = new window.Chart(chartCanvas, {
    data: { datasets },
    options: {
      animation: false,
      maintainAspectRatio: false,
      interaction: { mode: "nearest", intersect: false },
      layout: { padding: { top: 8 } },
      scales: {
        x: { type: "linear", title: { display: true, text: "Iteration" }, ticks: { precision: 0 } },
        reward: { position: "left", grace: "5%", title: { display: true, text: "Reward" } },
        completion: { position: "right", min: 0, max: 100, title: { display: true, text: "Completion [%]" }, grid: { drawOnChartArea: false } },
      },
      plugins: { legend: legendFor(chartCanvas.parentElement.clientWidth) },
      onResize: (current, size) => {
        current.config.options.plugins.legend = legendFor(size.width);
      },
    },
  });
}

// Evaluation: the results table

function addTrial(row) {
  const table = find("trials");
  if (!table) return;
  const body = table.tBodies[0];
  let line = body.querySelector(`tr[data-number="${row.number}"]`);
  if (!line) {
    line = document.createElement("tr");
    line.dataset.number = row.number;
    body.append(line);
  }
  const cells = [
    row.number, laptime(row.time_ms), `${row.progress.toFixed(1)}%`, row.status_display,
    row.off_tracks, row.crashes, laptime(row.penalty_ms), row.resets, row.against_line,
  ];
  line.replaceChildren(...cells.map((value, index) => Object.assign(document.createElement("td"), {
    className: index === 3 ? "" : "num", textContent: value,
  })));
  line.lastElementChild.dataset.againstLine = "";
  const empty = find("no-trials");
  if (empty) empty.hidden = true;
}

connect();
