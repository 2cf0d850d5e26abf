// A track's page: its racing line is copied with one press; while the line is being computed,
// the page looks again every few seconds and shows it once it is ready.
import { copyOnPress } from "../console/copy.js";

const root = document.querySelector("[data-track-line]");
const LOOK_AGAIN = 3000; // [ms]

copyOnPress(root.querySelector("[data-copy-line]"), root.querySelector("[data-line-literal]"),
  root.querySelector("[data-copy-status]"),
  { copied: "Copied: paste it above reward_function in your reward function." });

if (root.dataset.lineStatus === "computing") {
  setTimeout(() => window.location.reload(), LOOK_AGAIN);
}
