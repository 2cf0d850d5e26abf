// The model page: "Stop training" asks first, in a dialog that says what stopping does (the
// link opens a page that asks the same where dialogs are not supported).

const opener = document.querySelector("[data-stop-open]");
const dialog = document.querySelector("[data-stop-dialog]");

if (opener && dialog && typeof dialog.showModal === "function") {
  opener.addEventListener("click", (event) => {
    event.preventDefault();
    dialog.showModal();
  });
}
