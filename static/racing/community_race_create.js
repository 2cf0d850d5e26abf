// The community race form: only the fields of the chosen race type show (boxes for object
// avoidance, bot cars for head-to-bot).
const form = document.querySelector("[data-race-form]");
const raceType = form.querySelector("[name=race_type]");
const show = () => {
  for (const group of form.querySelectorAll("[data-race-fields]")) {
    group.hidden = group.dataset.raceFields !== raceType.value;
  }
};
raceType.addEventListener("change", show);
show();
