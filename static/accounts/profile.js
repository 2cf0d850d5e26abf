// The racer profile page: its preview shows the racer as leaderboards will, while they type; a
// new access token, shown once, is copied with one press.
import { copyOnPress } from "../console/copy.js";

const root = document.querySelector("[data-profile]");
const preview = root.querySelector("[data-profile-preview]");
const nameInput = root.querySelector("[data-racer-name]");
const country = root.querySelector("select[name=country]");

function update() {
  const name = nameInput.value.trim();
  const colour = root.querySelector("[data-avatar-colour]:checked");
  const avatar = preview.querySelector(".avatar");
  preview.querySelector(".racer-name").textContent = name;
  avatar.textContent = name.slice(0, 1).toUpperCase();
  if (colour) avatar.className = `avatar avatar-${colour.value}`;
  let code = preview.querySelector(".racer-country");
  if (!country.value) {
    code?.remove();
    return;
  }
  if (!code) {
    code = document.createElement("abbr");
    code.className = "racer-country";
    preview.querySelector("[data-racer]").append(code);
  }
  code.textContent = country.value;
  code.title = country.selectedOptions[0].textContent;
}

root.addEventListener("input", update);
root.addEventListener("change", update);

copyOnPress(document.querySelector("[data-copy-secret]"), document.querySelector("[data-secret]"),
  document.querySelector("[data-copy-status]"),
  { copied: "Copied: keep it where only your scripts read it." });
