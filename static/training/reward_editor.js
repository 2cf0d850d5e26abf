// The reward-function editor: CodeMirror on the textarea, examples, the racer's saved functions
// (the create form's "Start from"), and Validate without leaving the page. Errors come back with
// their line, which gets a marker in the gutter. On the reward-function page, what the racer has
// not saved is kept in sessionStorage, so Back (or a reload) brings it back.
const root = document.querySelector("[data-reward-editor]");
const examples = JSON.parse(document.getElementById("reward-examples").textContent);
const library = Object.fromEntries(
  Object.entries(JSON.parse(document.getElementById("reward-library")?.textContent || "{}"))
    .map(([pk, source]) => [pk, source.replace(/\r\n/g, "\n")]),
);
const status = root.querySelector("[data-status]");
const results = root.querySelector("[data-results]");
const validateButton = root.querySelector("[data-validate]");

const editor = window.CodeMirror.fromTextArea(document.getElementById("reward-source"), {
  mode: "python",
  lineNumbers: true,
  indentUnit: 4,
  tabSize: 4,
  indentWithTabs: false,
  matchBrackets: true,
  autoCloseBrackets: true,
  gutters: ["CodeMirror-linenumbers", "reward-errors"],
  extraKeys: {
    Tab: (cm) => cm.execCommand(cm.somethingSelected() ? "indentMore" : "insertSoftTab"),
    "Shift-Tab": "indentLess",
  },
  viewportMargin: Infinity,
});
let marked = [];

function clearMarks() {
  for (const line of marked) {
    editor.removeLineClass(line, "background", "reward-error-line");
  }
  editor.clearGutter("reward-errors");
  marked = [];
}

function markLine(number, message) {
  const line = number - 1;
  if (line < 0 || line >= editor.lineCount()) return;
  const marker = document.createElement("span");
  marker.className = "reward-error-marker";
  marker.textContent = "●";
  marker.title = message;
  editor.setGutterMarker(line, "reward-errors", marker);
  editor.addLineClass(line, "background", "reward-error-line");
  marked.push(line);
}

function text(tag, content, className) {
  const element = document.createElement(tag);
  element.textContent = content;
  if (className) element.className = className;
  return element;
}

function show(result) {
  results.hidden = false;
  const errors = root.querySelector("[data-errors]");
  errors.replaceChildren(...result.errors.map((error) => {
    const where = error.line ? ` (line ${error.line})` : "";
    const item = text("p", `${error.type}${where}: ${error.message}`);
    item.dataset.type = error.type;
    if (error.line) markLine(error.line, error.message);
    return item;
  }));
  errors.hidden = result.errors.length === 0;
  root.querySelector("[data-warnings]").replaceChildren(...result.warnings.map((warning) =>
    text("li", `Note${warning.line ? ` (line ${warning.line})` : ""}: ${warning.message}`)));
  root.querySelector("[data-samples]").replaceChildren(...result.samples.map((sample) => {
    const row = document.createElement("tr");
    row.dataset.situation = sample.situation;
    row.append(
      text("td", sample.situation),
      text("td", sample.description),
      text("td", sample.error ? sample.error : sample.reward.toPrecision(6), sample.error ? "field-error" : "num mono"),
    );
    return row;
  }));
  const logBox = root.querySelector("[data-log-box]");
  logBox.hidden = result.log.length === 0;
  root.querySelector("[data-log]").textContent = result.log.join("\n");
  status.textContent = result.valid ? "Valid: ready to train." : `${result.errors.length} error${result.errors.length === 1 ? "" : "s"} to fix.`;
  status.className = result.valid ? "badge badge-ok" : "badge badge-down";
}

async function validate() {
  clearMarks();
  validateButton.disabled = true;
  status.className = "muted";
  status.textContent = "Validating…";
  const body = new FormData();
  body.append("source", editor.getValue());
  body.append("track", document.querySelector(root.dataset.trackInput)?.value || "");
  try {
    const response = await fetch(root.dataset.validateUrl, {
      method: "POST",
      body,
      headers: { "X-CSRFToken": document.querySelector("[name=csrfmiddlewaretoken]").value },
      credentials: "same-origin",
    });
    const result = await response.json();
    if (!response.ok) {
      results.hidden = true;
      status.className = "badge badge-down";
      status.textContent = result.message;
      return;
    }
    show(result);
  } catch (error) {
    status.className = "badge badge-down";
    status.textContent = "The server could not be reached; your code is still here. Try again.";
  } finally {
    validateButton.disabled = false;
  }
}

// Replace the code with `source`, asking first unless the code is empty or one we offer as is.
function replaceCode(source, question) {
  const current = editor.getValue().trim();
  const offered = [...Object.values(examples), ...Object.values(library)];
  const known = offered.some((text) => text.trim() === current);
  if (current && !known && current !== source.trim() && !window.confirm(question)) return false;
  clearMarks();
  results.hidden = true;
  status.className = "muted";
  status.textContent = "";
  editor.setValue(source);
  editor.focus();
  return true;
}

validateButton.addEventListener("click", validate);
for (const button of document.querySelectorAll("[data-example]")) {
  button.addEventListener("click", () => {
    replaceCode(examples[button.dataset.example], "Replace your code with this example?");
  });
}

const picker = root.querySelector("[data-reward-pick]");
root.querySelector("[data-reward-load]")?.addEventListener("click", () => {
  const colon = picker.value.indexOf(":");
  const key = picker.value.slice(colon + 1);
  const source = picker.value.startsWith("saved:") ? library[key] : examples[key];
  if (source === undefined) {
    status.className = "badge badge-down";
    status.textContent = "Choose a saved function or an example first.";
    return;
  }
  const title = picker.selectedOptions[0].textContent;
  if (replaceCode(source, `Replace your code with “${title}”?`)) status.textContent = `Loaded “${title}”.`;
});

// What the server found when it refused to save: shown as if Validate had been pressed.
const refused = JSON.parse(document.getElementById("reward-validation-result")?.textContent || "null");
if (refused) show(refused);

const draftForm = root.closest("[data-draft-key]");
if (draftForm) keepDrafts(draftForm);

function keepDrafts(form) {
  const key = form.dataset.draftKey;
  const nameInput = form.querySelector("[data-reward-name]");
  const now = () => ({ source: editor.getValue(), name: nameInput ? nameInput.value : "" });
  const read = (name) => {
    try {
      return JSON.parse(window.sessionStorage.getItem(name));
    } catch {
      return null;
    }
  };
  const same = (a, b) => Boolean(a && b) && a.source === b.source && a.name === b.name;
  // A page the server rendered from a refused save shows unsaved code: keep it as the draft.
  const restorable = "draftRestore" in form.dataset;
  const saved = restorable ? now() : null;
  const clear = form.dataset.draftClear;  // the new-function draft, once it is this saved one
  if (clear && read(clear)?.source === saved?.source) window.sessionStorage.removeItem(clear);

  function remember() {
    try {
      if (same(now(), saved)) window.sessionStorage.removeItem(key);
      else window.sessionStorage.setItem(key, JSON.stringify(now()));
    } catch {
      // Storage full or refused: the code is still in the editor.
    }
  }

  const draft = read(key);
  const savedAs = draft && Object.keys(library).find((pk) => library[pk] === draft.source);
  if (restorable && savedAs && form.dataset.openUrl) {
    // Saved since ("Save and create a model", then Back): open the saved function instead.
    window.location.replace(form.dataset.openUrl.replace("/0/", `/${savedAs}/`));
    return;
  }
  if (restorable && draft && typeof draft.source === "string" && !same(draft, saved)) {
    editor.setValue(draft.source);
    if (nameInput) nameInput.value = draft.name || "";
    status.className = "muted";
    status.textContent = "What you had not saved is back. ";
    const discard = document.createElement("button");
    discard.type = "button";
    discard.className = "button button-secondary button-small";
    discard.textContent = "Discard it";
    discard.addEventListener("click", () => {
      editor.setValue(saved.source);
      if (nameInput) nameInput.value = saved.name;
      window.sessionStorage.removeItem(key);
      status.textContent = "";
    });
    status.append(discard);
  }
  if (!restorable) remember();
  editor.on("change", remember);
  nameInput?.addEventListener("input", remember);
}
