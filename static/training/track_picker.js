// The track picker (templates/training/includes/track_tools.html): the search box narrows the
// [data-track] items as one types, and the sort buttons reorder them in the page, in the orders
// the server uses for the Tracks list without JS (training/selectors.py TRACK_SORTS).

const number = (item, key) => Number(item.dataset[key]);
const byPosition = (a, b) => number(a, "position") - number(b, "position");

const SORTS = {
  "": byPosition,
  name: (a, b) => a.dataset.trackTitle.localeCompare(b.dataset.trackTitle) || byPosition(a, b),
  length: (a, b) => number(a, "length") - number(b, "length") || byPosition(a, b),
  width: (a, b) => number(a, "width") - number(b, "width") || byPosition(a, b),
  // Newest first; Pitlane's own tracks carry 9999 and come before DeepRacer's.
  season: (a, b) => number(b, "season") - number(a, "season") || byPosition(a, b),
};

function enhance(picker) {
  const tools = picker.querySelector("[data-track-tools]");
  const list = picker.querySelector("[data-track-list]");
  const items = [...list.querySelectorAll("[data-track]")];
  const search = tools.querySelector("[data-track-search]");
  const count = tools.querySelector("[data-track-count]");
  const buttons = [...tools.querySelectorAll("[data-track-sort]")];
  let sort = buttons.find((b) => b.getAttribute("aria-pressed") === "true")?.dataset.trackSort ?? "";

  const apply = () => {
    const words = search.value.toLowerCase().split(/\s+/).filter(Boolean);
    let shown = 0;
    for (const item of items) {
      item.hidden = !words.every((word) => item.dataset.track.includes(word));
      if (!item.hidden) shown += 1;
    }
    list.append(...[...items].sort(SORTS[sort] ?? byPosition));
    count.textContent = `${shown} of ${items.length} tracks`;
  };

  search.addEventListener("input", apply);
  // In a form that picks a track, Enter searches here rather than submit that form. The Tracks
  // list's search is a GET form of its own: there Enter and Find ask the server again, which can
  // widen a list it narrowed (?q=smile), where this only narrows what the page holds.
  if (search.form?.method !== "get") {
    search.addEventListener("keydown", (event) => {
      if (event.key === "Enter") {
        event.preventDefault();
        apply();
      }
    });
    tools.querySelector("[data-track-find]")?.setAttribute("hidden", "");
  }
  for (const button of buttons) {
    button.addEventListener("click", (event) => {
      event.preventDefault();
      sort = button.dataset.trackSort;
      // The Tracks list's form asks the server in the order shown when it searches again.
      const kept = tools.querySelector("input[type=hidden][name=sort]");
      if (kept) kept.value = sort;
      for (const other of buttons) other.setAttribute("aria-pressed", String(other === button));
      apply();
    });
  }
  tools.hidden = false;
  apply();
}

for (const picker of document.querySelectorAll("[data-track-picker]")) enhance(picker);
