// The create-model page: show the settings that apply, and edit the discrete action space as a
// table kept in the hidden "actions" field (JSON in model_metadata.json's form).
const form = document.querySelector("[data-model-form]");
const actionsField = form.querySelector("input[name=actions]");
const tableBody = form.querySelector("[data-actions]");

function checked(name) {
  return form.querySelector(`input[name=${name}]:checked`)?.value;
}

function showWhen(attribute, value) {
  for (const element of form.querySelectorAll(`[data-when-${attribute}]`)) {
    element.hidden = element.dataset[`when${attribute[0].toUpperCase()}${attribute.slice(1)}`] !== value;
  }
}

function refresh() {
  showWhen("race", checked("race_type"));
  showWhen("actions", checked("action_space_type"));
  showWhen("algorithm", checked("algorithm"));
  const vehicle = form.querySelector("select[name=vehicle]");
  form.querySelector("[data-sensors]").hidden = Boolean(vehicle && vehicle.value);
  const track = form.querySelector("input[name=track]:checked");
  const direction = form.querySelector("select[name=direction]");
  if (track && direction) {
    const allowed = track.dataset.directions.split(" ").filter(Boolean);
    for (const option of direction.options) option.disabled = !allowed.includes(option.value);
    if (!allowed.includes(direction.value)) direction.value = allowed[0];
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

function writeActions(actions) {
  actionsField.value = JSON.stringify(actions.map((action, index) => ({
    steering_angle: Number(action.steering_angle), speed: Number(action.speed), index,
  })));
  renderActions();
}

function numberInput(value, label, onChange) {
  const input = document.createElement("input");
  input.type = "number";
  input.step = "any";
  input.value = value;
  input.setAttribute("aria-label", label);
  input.addEventListener("change", () => onChange(input.value));
  return input;
}

function renderActions() {
  const actions = readActions();
  tableBody.replaceChildren(...actions.map((action, index) => {
    const row = document.createElement("tr");
    const number = document.createElement("td");
    number.textContent = index;
    const steering = document.createElement("td");
    steering.append(numberInput(action.steering_angle, `Steering of action ${index}`, (value) => {
      actions[index].steering_angle = value;
      writeActions(actions);
    }));
    const speed = document.createElement("td");
    speed.append(numberInput(action.speed, `Speed of action ${index}`, (value) => {
      actions[index].speed = value;
      writeActions(actions);
    }));
    const remove = document.createElement("td");
    const button = document.createElement("button");
    button.type = "button";
    button.className = "link-button danger";
    button.textContent = "Remove";
    button.addEventListener("click", () => {
      actions.splice(index, 1);
      writeActions(actions);
    });
    remove.append(button);
    row.append(number, steering, speed, remove);
    return row;
  }));
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
  writeActions(actions);
}

form.addEventListener("change", refresh);
form.querySelector("[data-generate]").addEventListener("click", generate);
form.querySelector("[data-add-action]").addEventListener("click", () => {
  writeActions([...readActions(), { steering_angle: 0, speed: 1 }]);
});
refresh();
renderActions();
