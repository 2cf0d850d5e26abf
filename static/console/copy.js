// One press copies what a page shows to be pasted elsewhere (an invitation link, a token shown
// once), from a read-only field: through the Clipboard API; where there is none (a page not
// served over HTTPS, an older browser), the field is selected and copied the old way where the
// browser still allows that, and otherwise the page says how to copy the selection by hand.
// The button is rendered disabled and enabled here, so a press never lands before it can work.
export function copyOnPress(button, field, status, { copied, done } = {}) {
  if (!button || !field) return;
  field.addEventListener("focus", () => field.select());
  button.disabled = false;
  const said = () => {
    status.textContent = copied;
    done?.();
  };
  button.addEventListener("click", async () => {
    try {
      await navigator.clipboard.writeText(field.value);
      said();
    } catch {
      field.focus();
      field.select();
      let copiedOldWay = false;
      try { copiedOldWay = document.execCommand("copy"); } catch { copiedOldWay = false; }
      if (copiedOldWay) said();
      else status.textContent = "Press Ctrl+C (⌘C on a Mac) to copy the selection.";
    }
  });
}
