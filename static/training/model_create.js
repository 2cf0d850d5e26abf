// The create-model page: show the settings that apply, and edit the discrete action space as a
// table kept in the hidden "actions" field (JSON in model_metadata.json's form, the actions
// numbered from 0 as there), drawn beside it as a fan. On a clone the table keeps its number of
// rows. After a refused submit the summary of the sections to fix takes the focus, so that a
// screen reader reads it first.
import { drawActionSpace } from "./action_space.js";
import { checked, refreshTrackAndRace, showWhen } from "./track_and_race.js";

const form = document.querySelector("[data-model-form]");
const actionsField = form.querySelector("input[name=actions]");
const tableBody = form.querySelector("[data-actions]");
const countLocked = form.querySelector("[data-add-action]") === null;
const fan = form.querySelector("[data-action-fan]");
const COLUMNS = { steering_angle: ["Steering angle", -30, 30], speed: ["Speed", 0.1, 4] };
// What the server found wrong with single actions ({index, columns, message} each): the cells
// stay marked until the racer changes them, or adds or removes a row.
let actionErrors = JSON.parse(document.getElementById("action-errors").textContent);

function refresh() {
  refreshTrackAndRace(form);
  showWhen(form, "actions", checked(form, "action_space_type"));
  showWhen(form, "algorithm", checked(form, "algorithm"));
  const vehicle = form.querySelector("select[name=vehicle]");
  form.querySelector("[data-sensors]").hidden = Boolean(vehicle && vehicle.value);
  drawFan();
}

function drawFan() {
  if (checked(form, "action_space_type") === "continuous") {
    const value = (name) => form.querySelector(`input[name=${name}]`).value;
    drawActionSpace(fan, {
      type: "continuous",
      ranges: {
        steering_angle: { low: value("steering_low"), high: value("steering_high") },
        speed: { low: value("speed_low"), high: value("speed_high") },
      },
    });
  } else {
    drawActionSpace(fan, { type: "discrete", actions: readActions() });
  }
}

function readActions() {
  try {
    const actions = JSON.parse(actionsField.value || "[]");
    return Array.isArray(actions) ? actions : [];
  } catch {
    return [];
  }
}

// A cell as the racer left it: a number, null when blank, or the text that is no number, so that
// the server can say which cell is wrong and how.
function cellValue(value) {
  const text = String(value ?? "").trim();
  if (text === "") return null;
  const number = Number(text);
  return Number.isFinite(number) ? number : text;
}

function saveActions(actions) {
  actionsField.value = JSON.stringify(actions.map((action, index) => ({
    steering_angle: cellValue(action.steering_angle), speed: cellValue(action.speed), index,
  })));
  drawFan();
}

function writeActions(actions) {
  saveActions(actions);
  renderActions();
}

function cellInput(actions, index, column) {
  const [label, min, max] = COLUMNS[column];
  const input = document.createElement("input");
  input.type = "number";
  input.step = "any";
  input.min = min;
  input.max = max;
  input.value = actions[index][column] ?? "";
  input.setAttribute("aria-label", `${label} of action ${index}`);
  input.addEventListener("change", () => {  // the table stays as it is: focus stays too
    actions[index][column] = input.value;
    saveActions(actions);
    actionErrors = actionErrors.filter((error) => error.index !== index || !error.columns.includes(column));
    markErrors();
  });
  const cell = document.createElement("td");
  cell.append(input);
  return cell;
}

// Mark each bad cell, with the message beside the last of an error's cells.
function markErrors() {
  for (const message of tableBody.querySelectorAll(".field-error")) message.remove();
  for (const input of tableBody.querySelectorAll("[aria-invalid]")) {
    input.removeAttribute("aria-invalid");
    input.removeAttribute("aria-describedby");
  }
  actionErrors.forEach((error, number) => {
    const row = tableBody.rows[error.index];
    if (!row) return;
    const id = `action-error-${number}`;
    const inputs = error.columns.map((column) => row.querySelector(`[data-column=${column}] input`));
    for (const input of inputs) {
      input.setAttribute("aria-invalid", "true");
      input.setAttribute("aria-describedby", id);
    }
    const message = document.createElement("p");
    message.className = "field-error";
    message.id = id;
    message.textContent = error.message;
    inputs.at(-1).after(message);
  });
}

function renderActions() {
  const actions = readActions();
  const rows = actions.map((action, index) => {
    const row = document.createElement("tr");
    const number = document.createElement("td");
    number.textContent = index;
    row.append(number);
    for (const column of Object.keys(COLUMNS)) {
      const cell = cellInput(actions, index, column);
      cell.dataset.column = column;
      row.append(cell);
    }
    if (!countLocked) {
      const remove = document.createElement("td");
      const button = document.createElement("button");
      button.type = "button";
      button.className = "link-button danger";
      button.textContent = "Remove";
      button.addEventListener("click", () => {
        actions.splice(index, 1);
        actionErrors = [];
        writeActions(actions);
      });
      remove.append(button);
      row.append(remove);
    }
    return row;
  });
  tableBody.replaceChildren(...rows);
  markErrors();
}

function generate() {
  const maxSteering = Number(document.getElementById("gen-steering").value);
  const steeringSteps = Number(document.getElementById("gen-steering-steps").value);
  const maxSpeed = Number(document.getElementById("gen-speed").value);
  const speedSteps = Number(document.getElementById("gen-speed-steps").value);
  const actions = [];
  for (let s = 1; s <= speedSteps; s += 1) {
    const speed = Math.round((maxSpeed * s / speedSteps) * 100) / 100;
    for (let a = 0; a < steeringSteps; a += 1) {
      const steering = -maxSteering + (2 * maxSteering * a) / (steeringSteps - 1);
      actions.push({ steering_angle: Math.round(steering * 10) / 10, speed });
    }
  }
  actionErrors = [];
  writeActions(actions);
}

form.addEventListener("change", refresh);
if (!countLocked) {
  form.querySelector("[data-generate]").addEventListener("click", generate);
  form.querySelector("[data-add-action]").addEventListener("click", () => {
    actionErrors = [];
    writeActions([...readActions(), { steering_angle: 0, speed: 1 }]);
  });
}
form.addEventListener("input", (event) => {
  if (event.target.closest("[data-when-actions=continuous]")) drawFan();
});
refresh();
renderActions();
form.querySelector("[data-error-summary]")?.focus();
