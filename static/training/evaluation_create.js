// The Evaluate page: only the chosen race type's settings show, as on the create-model page.
import { refreshTrackAndRace } from "./track_and_race.js";

const form = document.querySelector("[data-evaluation-form]");
form.addEventListener("change", () => refreshTrackAndRace(form));
refreshTrackAndRace(form);
