// The model page's Log panel, in time order as the download has it: the oldest line at the top,
// the newest at the bottom. The panel opens on the newest lines and follows new ones while the
// racer is at the bottom; scrolled up to read, it stays where they are and offers "Jump to
// newest". New lines are read again (the panel alone, data-log-url) when live.js announces an
// update of the job.

const panel = document.querySelector("[data-log-panel]");
const SLACK = 8; // [px] short of the bottom that still counts as at the bottom
const QUIET = 5000; // [ms] between two readings of the panel

const parts = () => ({
  log: panel.querySelector("[data-log]"),
  jump: panel.querySelector("[data-log-jump]"),
});

function atBottom(log) {
  return log.scrollHeight - log.scrollTop - log.clientHeight <= SLACK;
}

function toNewest() {
  const { log, jump } = parts();
  if (!log) return;
  log.scrollTop = log.scrollHeight;
  jump.hidden = true;
}

function watch() {
  const { log, jump } = parts();
  if (!log || log.dataset.watched) return;
  log.dataset.watched = "true";
  log.addEventListener("scroll", () => { jump.hidden = atBottom(log); });
  jump.addEventListener("click", toNewest);
}

let lastRead = performance.now(); // the page, panel included, was read just now
let pending = null;

function readSoon() {
  if (pending) return;
  pending = setTimeout(readAgain, Math.max(0, lastRead + QUIET - performance.now()));
}

async function readAgain() {
  lastRead = performance.now();
  try {
    const response = await fetch(panel.dataset.logUrl, { credentials: "same-origin" });
    if (!response.ok) return;
    const fresh = document.createElement("div"); // the panel's lines, rendered by the server
    fresh.innerHTML = await response.text();
    const { log } = parts();
    const freshLog = fresh.querySelector("[data-log]");
    if (log && freshLog) {
      const following = atBottom(log);
      log.replaceChildren(...freshLog.children);
      panel.querySelector("p.muted").replaceWith(fresh.querySelector("p.muted"));
      if (following) toNewest();
      else parts().jump.hidden = false;
    } else {
      panel.replaceChildren(...fresh.children);
      watch();
      toNewest();
    }
  } catch {
    // The next update tries again.
  } finally {
    pending = null;
  }
}

if (panel) {
  watch();
  toNewest();
  document.addEventListener("pitlane:job-update", readSoon);
}
