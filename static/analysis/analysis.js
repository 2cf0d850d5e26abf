// The Analysis tab: the recorded driving of a model's training (or of an evaluation) on the
// track, per iteration, by action and by episode, and re-scored with another reward function.
// The page brings the track and the per-iteration figures; what the racer picks (iterations,
// outcomes) is fetched from data.json (episodes, marks, action counts) and points.bin (the map's
// steps, float32 columns), so a ten-hour job draws as fast as a short one.

const root = document.querySelector("[data-analysis]");
const overview = root && JSON.parse(document.getElementById("analysis-overview").textContent);
const find = (name) => root.querySelector(`[data-${name}]`);
const COLUMNS = overview ? overview.point_columns : [];
const OUTCOME_NAMES = overview ? overview.outcomes.map(([value]) => value) : [];
const OUTCOME_LABELS = overview ? Object.fromEntries(overview.outcomes) : {};
const PAGE = 50; // episodes a table page shows
const MARKS = { off_track: "#d1242f", crashed: "#8250df" };
const LINE_COLOUR = "#ff2e93"; // the racing line: apart from the palettes, the white lap and the marks
const LINE = overview && overview.racing_line.status === "ready" ? overview.racing_line : null;

const state = {
  points: null, // { n, column(name) }
  picked: null,
  episode: null,
  rescoring: null,
  sort: { key: "iteration", descending: false },
  page: 0,
};
const charts = {};

// Colours

const VIRIDIS = overview ? overview.speed_colours : []; // the track page's too (training.track_lines)
const DIVERGING = ["#2166ac", "#4393c3", "#92c5de", "#d1e5f0", "#f7f7f7", "#fddbc7", "#f4a582", "#d6604d", "#b2182b"];
const CATEGORIES = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf",
  "#393b79", "#ad494a", "#637939", "#8c6d31", "#843c39", "#7b4173", "#3182bd", "#e6550d", "#31a354", "#756bb1"];

function scaleFor(name, values) {
  if (name === "action") {
    return { colour: (v) => CATEGORIES[Math.max(0, v) % CATEGORIES.length], legend: overview.actions.map((label, i) => [CATEGORIES[i % CATEGORIES.length], label]) };
  }
  if (name === "steer") {
    return ramp(DIVERGING, -30, 30, "°");
  }
  const finite = Array.from(values).filter(Number.isFinite).sort((a, b) => a - b);
  if (!finite.length) return ramp(VIRIDIS, 0, 1, "");
  const low = name === "speed" ? 0 : finite[Math.floor(finite.length * 0.02)];
  const high = finite[Math.min(finite.length - 1, Math.floor(finite.length * 0.98))];
  return ramp(VIRIDIS, low, high > low ? high : low + 1, name === "speed" ? " m/s" : "");
}

function ramp(palette, low, high, unit) {
  return {
    colour: (v) => palette[Math.max(0, Math.min(palette.length - 1, Math.floor(((v - low) / (high - low)) * palette.length)))],
    gradient: `linear-gradient(to right, ${palette.join(", ")})`,
    low: `${round(low)}${unit}`,
    high: `${round(high)}${unit}`,
  };
}

const round = (v) => (Math.abs(v) >= 100 ? v.toFixed(0) : Math.abs(v) >= 10 ? v.toFixed(1) : v.toFixed(2));

// The map

const canvas = root && find("map");
let view = null; // the transform from metres to canvas pixels
const MARGIN = 0.25; // [m] around what the map shows

// What the map shows: the track's borders and every point drawn over them (the steps, the
// marks, the fastest lap, or the episode followed), with a margin. A car that left the track
// is drawn where it went, not cut off at the canvas's edge.
function extent() {
  const box = [Infinity, -Infinity, Infinity, -Infinity];
  const add = (x, y) => {
    if (!Number.isFinite(x) || !Number.isFinite(y)) return;
    box[0] = Math.min(box[0], x);
    box[1] = Math.max(box[1], x);
    box[2] = Math.min(box[2], y);
    box[3] = Math.max(box[3], y);
  };
  const path = (points) => points?.forEach(([x, y]) => add(x, y));
  path(overview.track.inner);
  path(overview.track.outer);
  if (state.episode) {
    path(state.episode.path);
  } else {
    if (state.points && state.points.n) {
      const xs = state.points.column("x");
      const ys = state.points.column("y");
      for (let i = 0; i < state.points.n; i += 1) add(xs[i], ys[i]);
    }
    path(state.picked?.marks);
    path(state.fastest?.path);
  }
  return [box[0] - MARGIN, box[1] + MARGIN, box[2] - MARGIN, box[3] + MARGIN];
}

function fitMap() {
  const [minX, maxX, minY, maxY] = extent();
  const ratio = devicePixelRatio || 1;
  const width = canvas.clientWidth || 900;
  const height = Math.min(width * ((maxY - minY) / (maxX - minX)), innerHeight * 0.8) + 24;
  canvas.width = Math.round(width * ratio);
  canvas.height = Math.round(height * ratio);
  canvas.style.height = `${Math.round(height)}px`;
  const pad = 12 * ratio;
  const scale = Math.min((canvas.width - 2 * pad) / (maxX - minX), (canvas.height - 2 * pad) / (maxY - minY));
  const offsetX = (canvas.width - scale * (maxX - minX)) / 2;
  const offsetY = (canvas.height - scale * (maxY - minY)) / 2;
  view = { x: (x) => offsetX + (x - minX) * scale, y: (y) => canvas.height - offsetY - (y - minY) * scale, ratio, scale };
}

function drawTrack(context) {
  const { track } = overview;
  const line = (points) => {
    context.beginPath();
    points.forEach(([x, y], i) => (i ? context.lineTo(view.x(x), view.y(y)) : context.moveTo(view.x(x), view.y(y))));
  };
  context.fillStyle = "#ffffff";
  context.fillRect(0, 0, canvas.width, canvas.height);
  line(track.outer);
  context.closePath();
  track.inner.slice().reverse().forEach(([x, y], i) => (i ? context.lineTo(view.x(x), view.y(y)) : context.moveTo(view.x(x), view.y(y))));
  context.closePath();
  context.fillStyle = "#3a3f47";
  context.fill("evenodd");
  context.lineWidth = 1.5 * view.ratio;
  context.strokeStyle = "#f5f5f5";
  line(track.outer);
  context.stroke();
  line(track.inner);
  context.stroke();
  context.setLineDash([6 * view.ratio, 6 * view.ratio]);
  context.strokeStyle = "#fca311";
  line(track.centre);
  context.stroke();
  context.setLineDash([]);
  const [start, next] = track.centre;
  context.fillStyle = "#ffffff";
  context.beginPath();
  context.arc(view.x(start[0]), view.y(start[1]), 4 * view.ratio, 0, 2 * Math.PI);
  context.fill();
  context.strokeStyle = "#ffffff";
  context.beginPath();
  context.moveTo(view.x(start[0]), view.y(start[1]));
  context.lineTo(view.x(next[0]), view.y(next[1]));
  context.stroke();
}

function drawMap() {
  fitMap(); // what it shows may reach past the track: steps off it, another episode
  const context = canvas.getContext("2d");
  drawTrack(context);
  if (state.episode) {
    drawEpisode(context);
    return;
  }
  const points = state.points;
  if (!points || !points.n) {
    setText("map-caption", "No step of these episodes was recorded.");
    find("map-legend").replaceChildren();
    return;
  }
  const name = find("colour").value;
  const values = points.column(name === "rescored" ? "rescored" : name);
  const scale = scaleFor(name, values);
  const xs = points.column("x");
  const ys = points.column("y");
  const size = Math.max(2.5 * view.ratio, 0.04 * view.scale); // a point: 4 cm, or 2.5 px
  const byColour = new Map();
  for (let i = 0; i < points.n; i += 1) {
    if (!Number.isFinite(values[i])) continue;
    const colour = scale.colour(values[i]);
    let path = byColour.get(colour);
    if (!path) byColour.set(colour, (path = new Path2D()));
    path.rect(view.x(xs[i]) - size / 2, view.y(ys[i]) - size / 2, size, size);
  }
  byColour.forEach((path, colour) => {
    context.fillStyle = colour;
    context.fill(path);
  });
  drawMarks(context);
  if (state.fastest) drawPath(context, state.fastest.path, "#ffffff", 2.5);
  const line = drawRacingLine(context);
  legend(scale);
  const shown = `${points.n.toLocaleString()} steps`;
  const marks = state.picked ? state.picked.marks.length : 0;
  setText("map-caption", `${shown}${points.n >= 60000 ? " (evenly sampled)" : ""}; ✕ where a car left the track (${marks})${state.fastest ? "; white: the fastest lap" : ""}${line}.`);
}

// The racing line, thin, over the steps; thick where the lap compared with it loses most time.
// What it adds to the map's caption.
function drawRacingLine(context) {
  if (!LINE || !find("racing-line")?.checked) return "";
  drawPath(context, [...LINE.points, LINE.points[0]], LINE_COLOUR, 1.5);
  const { table } = comparedLap();
  if (!table || table.worst === null) return "; pink: the racing line";
  context.globalAlpha = 0.6;
  drawPath(context, table.worst_path, LINE_COLOUR, 7);
  context.globalAlpha = 1;
  return `; pink: the racing line, thick in sector ${table.worst + 1}, where the lap loses most time`;
}

function drawMarks(context) {
  if (!state.picked) return;
  const size = 4 * view.ratio;
  context.lineWidth = 2 * view.ratio;
  for (const [x, y, outcome] of state.picked.marks) {
    context.strokeStyle = MARKS[OUTCOME_NAMES[outcome]] || MARKS.off_track;
    context.beginPath();
    context.moveTo(view.x(x) - size, view.y(y) - size);
    context.lineTo(view.x(x) + size, view.y(y) + size);
    context.moveTo(view.x(x) + size, view.y(y) - size);
    context.lineTo(view.x(x) - size, view.y(y) + size);
    context.stroke();
  }
}

function drawPath(context, path, colour, width) {
  context.strokeStyle = colour;
  context.lineWidth = width * view.ratio;
  context.beginPath();
  path.forEach(([x, y], i) => (i ? context.lineTo(view.x(x), view.y(y)) : context.moveTo(view.x(x), view.y(y))));
  context.stroke();
}

function legend(scale) {
  const box = find("map-legend");
  if (scale.legend) {
    box.replaceChildren(...scale.legend.map(([colour, label]) => {
      const item = document.createElement("span");
      item.className = "legend-item";
      item.innerHTML = `<i style="background:${colour}"></i>`;
      item.append(label);
      return item;
    }));
    return;
  }
  box.innerHTML = `<span>${scale.low}</span><i class="legend-ramp" style="background:${scale.gradient}"></i><span>${scale.high}</span>`;
}

// One episode, step by step

async function openEpisode(iteration, number) {
  const response = await fetch(`${root.dataset.base}episode.json?iteration=${iteration}&episode=${number}`);
  const data = await response.json();
  if (!response.ok) {
    setText("map-caption", data.error || "The episode could not be read.");
    return;
  }
  state.episode = data;
  const slider = find("episode-step");
  slider.max = data.path.length - 1;
  slider.value = 0;
  const viewer = find("episode-viewer");
  viewer.hidden = false;
  const name = overview.evaluation ? `Trial ${number + 1}` : `Iteration ${iteration}, episode ${number}`;
  setText("episode-title", `${name}: ${OUTCOME_LABELS[data.outcome] || data.status}, ${data.seconds.toFixed(2)} s, reward ${data.reward.toFixed(2)}`);
  drawSectors();
  showStep();
  viewer.scrollIntoView({ block: "nearest" });
}

function showStep() {
  const index = Number(find("episode-step").value);
  const { episode } = state;
  const params = episode.params[index];
  setText("episode-step-label", `${index + 1} of ${episode.path.length} (${episode.statuses[index]})`);
  const shown = [["reward", episode.rewards[index]], ["action", episode.actions[index] >= 0 ? overview.actions[episode.actions[index]] : "continuous"], ...Object.entries(params)];
  find("episode-params").replaceChildren(...shown.flatMap(([name, value]) => {
    const term = document.createElement("dt");
    term.textContent = name;
    const description = document.createElement("dd");
    description.textContent = typeof value === "number" ? round(value) : Array.isArray(value) ? `[${value.join(", ")}]` : String(value);
    return [term, description];
  }));
  drawMap();
}

function drawEpisode(context) {
  const { episode } = state;
  const scale = scaleFor("reward", episode.rewards);
  const index = Number(find("episode-step").value);
  context.lineWidth = 3 * view.ratio;
  for (let i = 1; i < episode.path.length; i += 1) {
    context.strokeStyle = scale.colour(episode.rewards[i]);
    context.beginPath();
    context.moveTo(view.x(episode.path[i - 1][0]), view.y(episode.path[i - 1][1]));
    context.lineTo(view.x(episode.path[i][0]), view.y(episode.path[i][1]));
    context.stroke();
  }
  const line = drawRacingLine(context);
  const [x, y] = episode.path[index];
  const heading = (episode.params[index].heading * Math.PI) / 180;
  const size = 9 * view.ratio;
  context.save();
  context.translate(view.x(x), view.y(y));
  context.rotate(-heading);
  context.fillStyle = "#fca311";
  context.strokeStyle = "#14213d";
  context.beginPath();
  context.moveTo(size, 0);
  context.lineTo(-size * 0.6, size * 0.55);
  context.lineTo(-size * 0.6, -size * 0.55);
  context.closePath();
  context.fill();
  context.stroke();
  context.restore();
  legend(scale);
  setText("map-caption", `The episode's path, coloured by reward; the arrow is the car at the chosen step${line}.`);
}

// What the racer picked

function query() {
  const parameters = new URLSearchParams();
  const first = find("first");
  if (first) {
    parameters.set("first", first.value);
    parameters.set("last", find("last").value);
  }
  const outcomes = [...root.querySelectorAll("[data-outcome]:checked")].map((box) => box.value);
  parameters.set("outcomes", outcomes.join(","));
  return parameters;
}

let loading = 0;

async function load() {
  const ticket = (loading += 1);
  const parameters = query();
  if (!parameters.get("outcomes")) {
    state.points = { n: 0, column: () => new Float32Array(0) };
    state.picked = { episodes: [], marks: [], actions: { steer: [], speed: [], actions: [] }, fastest: null };
    state.fastest = null;
    render();
    return;
  }
  const pointsQuery = new URLSearchParams(parameters);
  if (state.rescoring) pointsQuery.set("rescoring", state.rescoring.id);
  setText("map-caption", "Loading…");
  const [picked, buffer] = await Promise.all([
    fetch(`${root.dataset.base}data.json?${parameters}`).then((r) => r.json()),
    fetch(`${root.dataset.base}points.bin?${pointsQuery}`).then((r) => r.arrayBuffer()),
  ]);
  if (ticket !== loading) return; // a newer choice is on its way
  const names = state.rescoring ? [...COLUMNS, "rescored"] : COLUMNS;
  const data = new Float32Array(buffer);
  const n = data.length / names.length;
  state.points = { n, column: (name) => data.subarray(names.indexOf(name) * n, (names.indexOf(name) + 1) * n) };
  state.picked = picked;
  state.page = 0;
  state.fastest = null;
  if (picked.fastest) {
    const [iteration, number] = picked.fastest;
    const response = await fetch(`${root.dataset.base}episode.json?iteration=${iteration}&episode=${number}`);
    if (response.ok && ticket === loading) state.fastest = await response.json();
  }
  render();
}

function render() {
  root.dataset.loaded = String(loading);
  drawMap();
  drawActions();
  drawEpisodes();
  drawSectors();
  const fastest = find("fastest");
  if (fastest) {
    fastest.textContent = state.fastest
      ? `Fastest picked: iteration ${state.fastest.iteration}, episode ${state.fastest.episode}, ${state.fastest.seconds.toFixed(2)} s (drawn on the map).`
      : "";
  }
}

// A complete lap against the racing line, sector by sector: the episode followed when it is a
// lap, else the fastest picked. The server times both (analysis/sectors.py); this only shows them.

function episodeName(episode) {
  return overview.evaluation ? `trial ${episode.episode + 1}` : `iteration ${episode.iteration}, episode ${episode.episode}`;
}

function comparedLap() {
  const followed = state.episode;
  if (followed?.sectors) return { table: followed.sectors, title: `The followed lap (${episodeName(followed)}, ${followed.seconds.toFixed(2)} s)` };
  const before = followed ? "The episode followed did not complete a lap, so the fastest picked is compared. " : "";
  if (state.fastest?.sectors) {
    return { table: state.fastest.sectors, title: `${before}The fastest picked lap (${episodeName(state.fastest)}, ${state.fastest.seconds.toFixed(2)} s)` };
  }
  if (state.fastest) return { note: state.fastest.sectors_note };
  return { note: `${before}No lap was completed in the episodes picked: a complete lap is compared with the racing line.` };
}

const seconds = (value) => `${value.toFixed(2)} s`;
const signed = (value) => `${value > 0.005 ? "+" : value < -0.005 ? "−" : "±"}${Math.abs(value).toFixed(2)} s`;
const speed = (value) => (value === null ? "—" : value.toFixed(2));

function drawSectors() {
  const panel = find("sectors");
  if (!panel || !LINE) return; // the panel says why there is no line
  const { table, title, note } = comparedLap();
  const element = find("sector-table");
  element.hidden = !table;
  if (!table) {
    setText("sectors-caption", note);
    return;
  }
  const start = table.standing ? "The line's times start from rest, as the episode did" : "The line's times are a flying lap's, as the episode did not start from rest";
  const drawn = find("racing-line")?.checked ? ": the thick pink stretch on the map" : "";
  const worst = table.worst === null ? "It loses no time to the line in any sector." : `It loses most time in sector ${table.worst + 1}${drawn}.`;
  setText("sectors-caption", `${title} against the racing line, in tenths of the lap from where it started. ${start}. ${worst}`);
  element.tBodies[0].replaceChildren(...table.rows.map((row, index) => {
    const line = document.createElement("tr");
    if (index === table.worst) line.className = "sector-worst";
    const cells = [`${row.sector} (${row.from}–${row.to}%)`, seconds(row.line), seconds(row.lap), signed(row.gap), `${speed(row.lap_speed)} / ${speed(row.line_speed)} m/s`];
    cells.forEach((text, column) => {
      const cell = document.createElement("td");
      cell.textContent = text;
      if (column) cell.className = "num";
      line.append(cell);
    });
    if (index === table.worst) {
      const flag = document.createElement("strong");
      flag.className = "sector-flag";
      flag.textContent = "where speed is lost";
      line.cells[0].append(" ", flag);
    }
    return line;
  }));
  const total = document.createElement("tr");
  [["Lap", ""], [seconds(table.line_total), "sector-total-line"], [seconds(table.lap_total), "sector-total-lap"], [signed(table.gap_total), ""], ["", ""]].forEach(([text, name], column) => {
    const cell = document.createElement(column ? "td" : "th");
    cell.textContent = text;
    if (column) cell.className = "num";
    if (name) cell.setAttribute(`data-${name}`, "");
    total.append(cell);
  });
  element.tFoot.replaceChildren(total);
}

// Per iteration

function drawIterations() {
  const rows = overview.iterations;
  const line = (key) => rows.filter((row) => row[key] !== null).map((row) => ({ x: row.iteration, y: row[key] }));
  const common = { type: "line", borderWidth: 2, pointRadius: 2 };
  const linear = { type: "linear", title: { display: true, text: "Iteration" }, ticks: { precision: 0 } };
  charts.iterations = new window.Chart(find("iteration-chart"), {
    data: {
      datasets: [
        { ...common, label: "Average reward", data: line("reward"), yAxisID: "reward", borderColor: "#0969da", backgroundColor: "#0969da" },
        { ...common, label: "Average progress [%]", data: line("progress"), yAxisID: "percent", borderColor: "#1a7f37", backgroundColor: "#1a7f37" },
        { ...common, label: "Laps completed [%]", data: line("completion"), yAxisID: "percent", borderColor: "#bf8700", backgroundColor: "#bf8700" },
      ],
    },
    options: {
      animation: false, maintainAspectRatio: false, interaction: { mode: "nearest", intersect: false },
      scales: { x: linear, reward: { position: "left", title: { display: true, text: "Reward" } }, percent: { position: "right", min: 0, max: 100, grid: { drawOnChartArea: false }, title: { display: true, text: "%" } } },
    },
  });
  charts.laps = new window.Chart(find("lap-chart"), {
    data: {
      datasets: [
        { ...common, label: "Best training lap [s]", data: line("best_lap"), borderColor: "#cf222e", backgroundColor: "#cf222e" },
        { ...common, label: "Median training lap [s]", data: line("median_lap"), borderColor: "#8250df", backgroundColor: "#8250df" },
      ],
    },
    options: { animation: false, maintainAspectRatio: false, scales: { x: linear, y: { title: { display: true, text: "Lap time [s]" } } } },
  });
}

// Actions

function drawActions() {
  const { actions } = state.picked;
  const discrete = !overview.continuous && actions.actions;
  const table = discrete ? actions.actions : actions.steer;
  const labels = discrete ? overview.actions : overview.steer_bins.map((bin) => `${bin}°`);
  const totals = labels.map((_, column) => table.reduce((sum, row) => sum + row[column], 0));
  const speeds = overview.speed_bins.map((_, column) => actions.speed.reduce((sum, row) => sum + row[column], 0));
  const datasets = [{ label: discrete ? "Times chosen" : "Steering chosen", data: totals, backgroundColor: discrete ? labels.map((_, i) => CATEGORIES[i % CATEGORIES.length]) : "#0969da" }];
  const config = {
    type: "bar",
    data: { labels, datasets },
    options: { animation: false, maintainAspectRatio: false, plugins: { legend: { display: false } }, scales: { y: { title: { display: true, text: "Steps" } } } },
  };
  if (overview.continuous) {
    config.data.datasets.push({ label: "Speed chosen", data: speeds, backgroundColor: "#1a7f37", xAxisID: "speed" });
    config.options.scales.speed = { type: "category", labels: overview.speed_bins.map((bin) => `${bin} m/s`), position: "top" };
    config.options.plugins.legend.display = true;
  }
  charts.actions?.destroy();
  charts.actions = new window.Chart(find("action-chart"), config);
  const section = find("section-table");
  const head = `<thead><tr><th>Lap</th>${labels.map((label) => `<th class="num">${escape(label)}</th>`).join("")}</tr></thead>`;
  const body = table.map((row, index) => {
    const sum = row.reduce((a, b) => a + b, 0) || 1;
    const cells = row.map((count) => {
      const share = count / sum;
      return `<td class="num" style="background: rgb(9 105 218 / ${(share * 0.45).toFixed(2)})">${(100 * share).toFixed(0)}%</td>`;
    });
    return `<tr><th>${index * 10}-${index * 10 + 10}%</th>${cells.join("")}</tr>`;
  });
  section.innerHTML = section.querySelector("caption").outerHTML + head + `<tbody>${body.join("")}</tbody>`;
}

const escape = (text) => String(text).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]);

// Episodes

const EPISODE_KEYS = ["iteration", "episode", "start", "steps", "progress", "seconds", "outcome", "reward"];

function rescoredTotal(row) {
  const totals = state.rescoring && state.rescoring.episodes[String(row[0])];
  if (!totals) return null;
  const found = totals.find(([number]) => number === row[1]);
  return found ? found[1] : null;
}

function drawEpisodes() {
  const rows = state.picked.episodes.slice();
  const { key, descending } = state.sort;
  const value = (row) => (key === "rescored" ? rescoredTotal(row) ?? -Infinity : row[EPISODE_KEYS.indexOf(key)]);
  rows.sort((a, b) => (value(a) < value(b) ? -1 : value(a) > value(b) ? 1 : 0) * (descending ? -1 : 1));
  const pages = Math.max(1, Math.ceil(rows.length / PAGE));
  state.page = Math.min(state.page, pages - 1);
  const shown = rows.slice(state.page * PAGE, (state.page + 1) * PAGE);
  const body = find("episode-table").tBodies[0];
  body.replaceChildren(...shown.map((row) => {
    const [iteration, number, start, steps, progress, seconds, outcome, reward] = row;
    const line = document.createElement("tr");
    line.dataset.iteration = iteration;
    line.dataset.episode = number;
    const cells = [
      ...(overview.evaluation ? [] : [iteration]),
      overview.evaluation ? number + 1 : number, start, steps, `${progress.toFixed(1)}%`, `${seconds.toFixed(2)} s`,
      OUTCOME_LABELS[OUTCOME_NAMES[outcome]], reward.toFixed(2),
    ];
    if (state.rescoring) cells.push(rescoredTotal(row)?.toFixed(2) ?? "—");
    cells.forEach((text, index) => {
      const cell = document.createElement("td");
      cell.textContent = text;
      if (index !== cells.length - (state.rescoring ? 3 : 2)) cell.className = "num";
      line.append(cell);
    });
    const open = document.createElement("td");
    open.innerHTML = '<button type="button" class="link-button" data-open-episode>Show</button>';
    line.append(open);
    return line;
  }));
  setText("episode-count", `${rows.length.toLocaleString()} episode${rows.length === 1 ? "" : "s"}; click a column to sort, Show to follow one on the map.`);
  setText("page-label", `Page ${state.page + 1} of ${pages}`);
  find("rescored-column").hidden = !state.rescoring;
}

// Re-scoring

async function rescore(event) {
  event.preventDefault();
  const form = event.target;
  const errors = find("rescore-errors");
  errors.hidden = true;
  const response = await fetch(form.action, { method: "POST", body: new FormData(form), headers: { "X-Requested-With": "fetch" } });
  const data = await response.json();
  if (!response.ok) {
    errors.replaceChildren(...Object.values(data.errors || {}).flat().map((error) => {
      const line = document.createElement("p");
      line.textContent = error.message;
      return line;
    }));
    errors.hidden = false;
    return;
  }
  follow(data);
}

// The "Start from" choice fills the editor with a function the racer already has; an edit makes
// the code pasted again, so what is sent is always what the editor shows.
function chooseRewardFunction(form) {
  const sources = JSON.parse(document.getElementById("rescore-sources").textContent);
  const chosen = form.elements.saved;
  const code = form.elements.reward_function;
  chosen.addEventListener("change", () => {
    if (chosen.value) code.value = sources[chosen.value];
  });
  code.addEventListener("input", () => {
    chosen.value = "";
  });
}

// Where a queued re-scoring stands: racers take turns, so the place is among every racer's.
function waiting(place) {
  if (place === null || place === undefined) return "Waiting for a re-scoring worker…";
  if (place === 0) return "Waiting: yours is the next re-scoring a worker takes up.";
  const others = place === 1 ? "1 re-scoring goes" : `${place} re-scorings go`;
  return `Waiting: ${others} before yours (racers take turns).`;
}

async function follow(data) {
  const status = find("rescore-status");
  while (data.status === "QUEUED" || data.status === "RUNNING") {
    status.textContent = data.status === "QUEUED"
      ? waiting(data.place)
      : `Scoring: ${data.steps.toLocaleString()} of ${data.total_steps.toLocaleString()} steps.`;
    await new Promise((resolve) => setTimeout(resolve, 1000));
    const response = await fetch(data.url).catch(() => null);
    if (response?.status === 404) {
      status.textContent = "This re-scoring is gone: its model or its training was deleted.";
      return;
    }
    if (response?.ok) data = await response.json(); // else the console is busy: ask again
  }
  if (data.status === "FAILED") {
    status.innerHTML = `<p class="field-error"></p>`;
    status.firstChild.textContent = data.failure;
    return;
  }
  state.rescoring = data;
  status.textContent = `Scored ${data.total_steps.toLocaleString()} steps${overview.evaluation ? "" : ` of iterations ${data.first} to ${data.last}`}. The map can now be coloured by the re-scored reward; the episodes table has its totals.`;
  if (data.log.length) {
    const printed = document.createElement("pre");
    printed.textContent = data.log.join("\n");
    status.append(printed);
  }
  find("colour-rescored").disabled = false;
  find("colour").value = "rescored";
  drawComparison();
  await load();
}

function drawComparison() {
  const pairs = [];
  for (const row of state.picked?.episodes ?? []) {
    const total = rescoredTotal(row);
    if (total !== null) pairs.push({ x: row[7], y: total });
  }
  find("rescore-figure").hidden = false;
  charts.rescore?.destroy();
  charts.rescore = new window.Chart(find("rescore-chart"), {
    type: "scatter",
    data: { datasets: [{ label: "Episodes", data: pairs, backgroundColor: "rgb(9 105 218 / 0.55)" }] },
    options: {
      animation: false, maintainAspectRatio: false, plugins: { legend: { display: false } },
      scales: { x: { title: { display: true, text: "Reward trained with" } }, y: { title: { display: true, text: "Re-scored reward" } } },
    },
  });
}

// Wiring

function setText(name, text) {
  const element = find(name);
  if (element) element.textContent = text;
}

function download(event) {
  const link = event.target.closest("[data-download]");
  if (!link) return;
  const which = link.dataset.download;
  const source = which === "map" ? canvas : charts[which]?.canvas;
  if (!source) return;
  link.href = source.toDataURL("image/png");
  link.download = `${document.title.replace(/\W+/g, "-")}-${which}.png`;
}

if (root) {
  let timer = null;
  const later = () => {
    clearTimeout(timer);
    timer = setTimeout(load, 250);
  };
  find("analysis-filters").addEventListener("change", (event) => {
    if (event.target.matches("[data-racing-line]")) drawSectors(); // its caption names the map's stretch
    if (event.target.matches("[data-colour], [data-racing-line]")) drawMap();
    else later();
  });
  find("analysis-filters").addEventListener("submit", (event) => event.preventDefault());
  find("episode-step").addEventListener("input", showStep);
  find("episode-close").addEventListener("click", () => {
    state.episode = null;
    find("episode-viewer").hidden = true;
    drawSectors();
    drawMap();
  });
  find("episode-table").addEventListener("click", (event) => {
    const sort = event.target.closest("[data-sort]");
    if (sort) {
      const key = sort.dataset.sort;
      state.sort = { key, descending: state.sort.key === key ? !state.sort.descending : key !== "iteration" && key !== "episode" };
      drawEpisodes();
    }
    const open = event.target.closest("[data-open-episode]");
    if (open) {
      const row = open.closest("tr");
      openEpisode(Number(row.dataset.iteration), Number(row.dataset.episode));
    }
  });
  root.querySelectorAll("[data-page]").forEach((button) => button.addEventListener("click", () => {
    state.page = Math.max(0, state.page + Number(button.dataset.page));
    drawEpisodes();
  }));
  find("rescore-form").addEventListener("submit", rescore);
  chooseRewardFunction(find("rescore-form"));
  root.querySelectorAll("[data-rescoring-url]").forEach((button) => button.addEventListener("click", async () => {
    follow(await (await fetch(button.dataset.rescoringUrl)).json());
  }));
  root.addEventListener("click", download);
  addEventListener("resize", () => {
    view = null;
    drawMap();
  });
  if (!overview.evaluation && window.Chart) drawIterations();
  load();
}
