// Managing a community race: copy its invitation link, and ask in a dialog before closing the
// race, taking a racer out or replacing the link.
const dialog = document.querySelector("[data-confirm-dialog]");
const yes = dialog.querySelector("[data-confirm-yes]");
let pending = null;

for (const form of document.querySelectorAll("form[data-confirm]")) {
  form.addEventListener("submit", (event) => {
    event.preventDefault();
    pending = form;
    dialog.querySelector("[data-confirm-title]").textContent = form.dataset.confirmTitle;
    dialog.querySelector("[data-confirm-text]").textContent = form.dataset.confirm;
    yes.textContent = form.dataset.confirmButton;
    dialog.showModal();
  });
}
yes.addEventListener("click", () => {
  dialog.close();
  pending.submit(); // a form's submit() skips its submit event: asked once is enough
});
dialog.querySelector("[data-confirm-no]").addEventListener("click", () => dialog.close());

const link = document.querySelector("[data-invite-link]");
const copy = document.querySelector("[data-copy-invite]");
const status = document.querySelector("[data-copy-status]");
const COPIED = "Copied: paste it in a message to the racers you invite.";

function copied() {
  status.textContent = COPIED;
  copy.textContent = "Copied";
  setTimeout(() => { copy.textContent = "Copy the link"; }, 2000);
}

if (link && copy) {
  link.addEventListener("focus", () => link.select());
  copy.addEventListener("click", async () => {
    try {
      await navigator.clipboard.writeText(link.value);
      copied();
    } catch {
      // No Clipboard API (a page not served over HTTPS, an older browser): select the link, and
      // copy it the old way where the browser still allows that.
      link.focus();
      link.select();
      let done = false;
      try { done = document.execCommand("copy"); } catch { done = false; }
      if (done) copied();
      else status.textContent = "Press Ctrl+C (⌘C on a Mac) to copy the selected link.";
    }
  });
}
