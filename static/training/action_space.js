// The action space drawn as DeepRacer's create page drew it: seen from above, the car at the
// bottom, each discrete action a ray whose angle is its steering (positive is left, drawn to the
// left) and whose length is its speed; a continuous space is the sector of its steering range
// between its lowest and highest speed. On load it draws each [data-action-fan] whose
// [data-action-space-from] names a json_script of a model's action space; the create page draws
// its own as it changes.

const SVG = "http://www.w3.org/2000/svg";
const RADIUS = 100; // the longest ray, in the drawing's units
const MAX_STEERING = 30; // [°] DeepRacer's range, drawn as dashed guides

function element(name, attributes) {
  const node = document.createElementNS(SVG, name);
  for (const [key, value] of Object.entries(attributes)) node.setAttribute(key, value);
  return node;
}

// The point at ``radius`` along the steering angle ``degrees`` (positive is left).
function point(degrees, radius) {
  const angle = (degrees * Math.PI) / 180;
  return [-radius * Math.sin(angle), -radius * Math.cos(angle)].map((v) => v.toFixed(2));
}

function number(value) {
  if (value === null || value === undefined || String(value).trim() === "") return null;
  const parsed = Number(value);
  return Number.isFinite(parsed) ? parsed : null;
}

function guides(svg, speedScale) {
  for (const degrees of [-MAX_STEERING, MAX_STEERING]) {
    const [x, y] = point(degrees, RADIUS);
    svg.append(element("line", { x1: 0, y1: 0, x2: x, y2: y, class: "fan-guide" }));
  }
  const [x1, y1] = point(-MAX_STEERING, RADIUS);
  const [x2, y2] = point(MAX_STEERING, RADIUS);
  svg.append(element("path", { d: `M ${x1} ${y1} A ${RADIUS} ${RADIUS} 0 0 0 ${x2} ${y2}`, class: "fan-guide" }));
  const label = element("text", { x: 0, y: -RADIUS - 4, class: "fan-label", "text-anchor": "middle" });
  label.textContent = `${speedScale} m/s`;
  svg.append(label);
  const left = element("text", { x: -58, y: 8, class: "fan-label", "text-anchor": "start" });
  left.textContent = "left";
  const right = element("text", { x: 58, y: 8, class: "fan-label", "text-anchor": "end" });
  right.textContent = "right";
  svg.append(left, right);
}

function title(node, text) {
  const tip = document.createElementNS(SVG, "title");
  tip.textContent = text;
  node.append(tip);
}

function drawDiscrete(svg, actions) {
  const drawn = actions
    .map((action, index) => ({ index, steering: number(action.steering_angle), speed: number(action.speed) }))
    .filter((action) => action.steering !== null && action.speed !== null && action.speed > 0);
  const scale = Math.max(...drawn.map((action) => action.speed), 0) || 1;
  guides(svg, scale);
  for (const action of drawn) {
    const [x, y] = point(action.steering, (RADIUS * action.speed) / scale);
    const ray = element("line", { x1: 0, y1: 0, x2: x, y2: y, class: "fan-ray", "data-action-ray": action.index });
    title(ray, `Action ${action.index}: steering ${action.steering}°, ${action.speed} m/s`);
    svg.append(ray, element("circle", { cx: x, cy: y, r: 2.5, class: "fan-tip" }));
  }
  const speeds = drawn.map((action) => action.speed);
  const [slowest, fastest] = [Math.min(...speeds), Math.max(...speeds)];
  const span = slowest === fastest ? `${fastest} m/s` : `${slowest} to ${fastest} m/s`;
  svg.setAttribute("aria-label", drawn.length
    ? `Action space fan: ${drawn.length} action${drawn.length === 1 ? "" : "s"}, ${span}.`
    : "Action space fan: no action to draw yet.");
}

function drawContinuous(svg, space) {
  const low = number(space.steering_angle?.low);
  const high = number(space.steering_angle?.high);
  const slow = number(space.speed?.low);
  const fast = number(space.speed?.high);
  if ([low, high, slow, fast].includes(null) || fast <= 0) {
    guides(svg, 1);
    svg.setAttribute("aria-label", "Action space fan: the ranges are not complete.");
    return;
  }
  const [right, left] = [Math.min(low, high), Math.max(low, high)];
  const outer = RADIUS;
  const inner = (RADIUS * Math.max(0, Math.min(slow, fast))) / Math.max(slow, fast);
  guides(svg, Math.max(slow, fast));
  const [ox1, oy1] = point(right, outer);
  const [ox2, oy2] = point(left, outer);
  const [ix2, iy2] = point(left, inner);
  const [ix1, iy1] = point(right, inner);
  const sector = element("path", {
    d: `M ${ox1} ${oy1} A ${outer} ${outer} 0 0 0 ${ox2} ${oy2} L ${ix2} ${iy2} A ${inner} ${inner} 0 0 1 ${ix1} ${iy1} Z`,
    class: "fan-sector",
    "data-action-sector": "",
  });
  const text = `steering ${low} to ${high}°, ${slow} to ${fast} m/s`;
  title(sector, text);
  svg.append(sector);
  svg.setAttribute("aria-label", `Action space fan: ${text}.`);
}

// Draw ``space`` ({type: "discrete", actions} or {type: "continuous", ranges}) into ``svg``.
export function drawActionSpace(svg, space) {
  svg.replaceChildren();
  svg.append(element("circle", { cx: 0, cy: 0, r: 3, class: "fan-car" }));
  if (space.type === "continuous") drawContinuous(svg, space.ranges);
  else drawDiscrete(svg, space.actions);
}

// A model's action space as model_metadata.json holds it: a list of actions, or the ranges.
for (const svg of document.querySelectorAll("[data-action-fan][data-action-space-from]")) {
  const source = document.getElementById(svg.dataset.actionSpaceFrom);
  if (!source) continue;
  const space = JSON.parse(source.textContent);
  drawActionSpace(svg, Array.isArray(space)
    ? { type: "discrete", actions: space }
    : { type: "continuous", ranges: space });
}
