// Forms whose answer waits on a checker (a reward function run in the sandbox, an archive read):
// on submit, say so beside the buttons and keep a second click from sending the work twice.
// A form opts in with data-busy="What the racer reads while it waits". The listener is the
// document's, so that it hears a submit after the form's own scripts have had their say.
document.addEventListener("submit", (event) => {
  const form = event.target;
  if (!form.matches("form[data-busy]") || event.defaultPrevented) return; // not sent, or not ours
  if (form.dataset.sending) {
    event.preventDefault();
    return;
  }
  form.dataset.sending = "true";
  for (const button of form.querySelectorAll("button[type=submit]")) {
    // Not `disabled`: a disabled submitter would drop its name=value from the form's data.
    button.setAttribute("aria-disabled", "true");
  }
  let status = form.querySelector("[data-busy-status]");
  if (!status) {
    status = document.createElement("span");
    status.className = "muted";
    status.dataset.busyStatus = "";
    status.setAttribute("role", "status");
    (event.submitter || form.querySelector("button[type=submit]") || form).after(status);
  }
  status.textContent = form.dataset.busy;
});
// Back from the browser's cache (the back button): the form can be sent again.
window.addEventListener("pageshow", () => {
  for (const form of document.querySelectorAll("form[data-sending]")) {
    delete form.dataset.sending;
    form.querySelectorAll("[aria-disabled]").forEach((button) => button.removeAttribute("aria-disabled"));
    form.querySelector("[data-busy-status]")?.remove();
  }
});
