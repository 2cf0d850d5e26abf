// The reward-function editor: CodeMirror on the textarea, examples, and Validate without leaving
// the page. Errors come back with their line, which gets a marker in the gutter.
const root = document.querySelector("[data-reward-editor]");
const examples = JSON.parse(document.getElementById("reward-examples").textContent);
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

validateButton.addEventListener("click", validate);
for (const button of document.querySelectorAll("[data-example]")) {
  button.addEventListener("click", () => {
    const current = editor.getValue().trim();
    const isExample = Object.values(examples).some((source) => source.trim() === current);
    if (current && !isExample && !window.confirm("Replace your code with this example?")) return;
    clearMarks();
    results.hidden = true;
    status.textContent = "";
    editor.setValue(examples[button.dataset.example]);
    editor.focus();
  });
}
