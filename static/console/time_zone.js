// Dates in the racer's time zone (console/time_zones.py): tell the server the browser's zone in a
// cookie, and if this page was written for another zone (the first page a browser sees), write
// its <time data-when> elements again in the browser's zone, as the server will from now on.
const zone = Intl.DateTimeFormat().resolvedOptions().timeZone;
const COOKIE = "pitlane_tz";
const sent = document.cookie.split("; ").find((pair) => pair.startsWith(`${COOKIE}=`));

function parts(date, options) {
  const found = {};
  for (const part of new Intl.DateTimeFormat("en-GB", { timeZone: zone, ...options }).formatToParts(date)) {
    found[part.type] = part.value;
  }
  return found;
}

// console.time_zones.FORMATS: Django's "j M Y, H:i" and "H:i:s" (Intl's own short months differ: "Sept").
const MONTHS = ["Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec"];

function label(date, style) {
  const p = parts(date, {
    day: "numeric", month: "numeric", year: "numeric",
    hour: "2-digit", minute: "2-digit", second: "2-digit", hourCycle: "h23",
  });
  return style === "time" ? `${p.hour}:${p.minute}:${p.second}` : `${Number(p.day)} ${MONTHS[p.month - 1]} ${p.year}, ${p.hour}:${p.minute}`;
}

// IANA names (Area/City, letters, digits, _ + -) are cookie-safe as they are.
if (zone && (!sent || sent.split("=")[1] !== zone)) {
  document.cookie = `${COOKIE}=${zone}; path=/; max-age=31536000; samesite=lax`;
  for (const element of document.querySelectorAll("time[data-when]")) {
    element.textContent = label(new Date(element.dateTime), element.dataset.when);
  }
  const named = document.querySelector("[data-time-zone]");
  if (named) named.textContent = zone;
}
