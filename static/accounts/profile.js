// The racer profile page: its preview shows the racer as leaderboards will, while they type.
const root = document.querySelector("[data-profile]");
const preview = root.querySelector("[data-profile-preview]");
const nameInput = root.querySelector("[data-racer-name]");
const country = root.querySelector("select[name=country]");

function flag(code) {
  return [...code].map((letter) => String.fromCodePoint(0x1f1e6 + letter.charCodeAt(0) - 65)).join("");
}

function update() {
  const name = nameInput.value.trim();
  const colour = root.querySelector("[data-avatar-colour]:checked");
  const avatar = preview.querySelector(".avatar");
  preview.querySelector(".racer-name").textContent = name;
  avatar.textContent = name.slice(0, 1).toUpperCase();
  if (colour) avatar.className = `avatar avatar-${colour.value}`;
  let place = preview.querySelector(".racer-country");
  if (!country.value) {
    place?.remove();
    return;
  }
  if (!place) {
    place = document.createElement("span");
    place.className = "racer-country";
    place.innerHTML = '<span aria-hidden="true"></span> <abbr></abbr>';
    preview.querySelector("[data-racer]").append(place);
  }
  const countryName = country.selectedOptions[0].textContent;
  place.title = countryName;
  place.querySelector("span").textContent = flag(country.value);
  place.querySelector("abbr").textContent = country.value;
  place.querySelector("abbr").title = countryName;
}

root.addEventListener("input", update);
root.addEventListener("change", update);
