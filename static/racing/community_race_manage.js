// Managing a community race: copy its invitation link, and ask in a dialog before closing the
// race, taking a racer out or replacing the link.
import { copyOnPress } from "../console/copy.js";

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

const copy = document.querySelector("[data-copy-invite]");
copyOnPress(copy, document.querySelector("[data-invite-link]"),
  document.querySelector("[data-copy-status]"), {
    copied: "Copied: paste it in a message to the racers you invite.",
    done: () => {
      copy.textContent = "Copied";
      setTimeout(() => { copy.textContent = "Copy the link"; }, 2000);
    },
  });
