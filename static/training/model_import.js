// The import page: the name is checked as the racer types (and when they leave the field), so a
// name already taken is said before a large archive is uploaded; the form is not sent while it is.
// On the preview of an import that would train, the same for its name, and the direction offers
// only the ways the chosen track is driven.
const form = document.querySelector("[data-import-form]");
const input = form.querySelector("[data-name-check]");
const field = form.querySelector("[data-name-field]");
const status = form.querySelector("[data-name-status]");
let problem = "";
let asked = "";
let timer = null;

function show(message) {
  problem = message;
  status.textContent = message;
  field.classList.toggle("field-invalid", Boolean(message));
  if (message) input.setAttribute("aria-invalid", "true");
  else input.removeAttribute("aria-invalid");
}

async function check() {
  clearTimeout(timer);
  const name = input.value.trim();
  if (name === asked) return;
  asked = name;
  if (name === "") {
    show("");
    return;
  }
  const url = `${input.dataset.nameCheck}?${new URLSearchParams({ name })}`;
  try {
    const response = await fetch(url, { headers: { Accept: "application/json" } });
    if (!response.ok) return; // the server checks again when the form is sent
    const answer = await response.json();
    if (answer.name === input.value.trim()) show(answer.ok ? "" : answer.message);
  } catch {
    asked = ""; // offline for a moment: ask again next time
  }
}

input.addEventListener("input", () => {
  clearTimeout(timer);
  timer = setTimeout(check, 300);
});
input.addEventListener("blur", check);
let checked = false; // the name was just checked: this submit goes through
form.addEventListener("submit", async (event) => {
  if (checked) {
    checked = false;
  } else if (input.value.trim() !== asked) {
    event.preventDefault();
    await check();
    if (!problem) {
      checked = true;
      form.requestSubmit(); // a submit event again, for console/busy.js to hear
    }
  } else if (problem) {
    event.preventDefault();
  }
  if (problem) input.focus();
});

const track = form.querySelector("[data-import-track]");
const direction = form.querySelector("[data-import-direction]");

function directionsFollowTrack() {
  const allowed = track.selectedOptions[0]?.dataset.directions.trim().split(/\s+/) ?? [];
  for (const option of direction.options) option.disabled = !allowed.includes(option.value);
  if (direction.selectedOptions[0]?.disabled && allowed.length) direction.value = allowed[0];
}

if (track && direction) {
  track.addEventListener("change", directionsFollowTrack);
  directionsFollowTrack();
}
