// The track and race settings that the create-model and Evaluate pages share
// (templates/training/includes/race_type_fields.html): a race type's boxes or bot cars show only
// while it is chosen, and the direction offers only what the chosen track can be driven.

export function checked(form, name) {
  return form.querySelector(`input[name=${name}]:checked`)?.value;
}

// Show the elements marked data-when-<attribute>="<value>" for this value, hide the others.
export function showWhen(form, attribute, value) {
  const key = `when${attribute[0].toUpperCase()}${attribute.slice(1)}`;
  for (const element of form.querySelectorAll(`[data-when-${attribute}]`)) {
    element.hidden = element.dataset[key] !== value;
  }
}

export function refreshTrackAndRace(form) {
  showWhen(form, "race", checked(form, "race_type"));
  const track = form.querySelector("input[name=track]:checked");
  const direction = form.querySelector("select[name=direction]");
  if (track && direction) {
    const allowed = track.dataset.directions.split(" ").filter(Boolean);
    for (const option of direction.options) option.disabled = !allowed.includes(option.value);
    if (!allowed.includes(direction.value)) direction.value = allowed[0];
  }
}
