// What every page must pass, measured in the browser (tests/browser/checks.py).

// WCAG 2.1 contrast of every visible piece of text against what is really behind it: the
// backgrounds of its ancestors, blended, up to the first opaque one. Text over an image or a
// gradient is not judged; disabled controls are exempt, as WCAG exempts them.
window.pitlaneContrastFailures =
() => {
  const parse = (text) => {
    const found = text.match(/rgba?\(([^)]+)\)/);
    if (!found) return null;
    const parts = found[1].split(/[\s,\/]+/).filter(Boolean).map(Number);
    return [parts[0], parts[1], parts[2], parts.length > 3 ? parts[3] : 1];
  };
  const over = (top, bottom) => [0, 1, 2].map((i) => top[i] * top[3] + bottom[i] * (1 - top[3])).concat(1);
  const luminance = (colour) => {
    const [r, g, b] = colour.slice(0, 3).map((v) => {
      v /= 255;
      return v <= 0.03928 ? v / 12.92 : ((v + 0.055) / 1.055) ** 2.4;
    });
    return 0.2126 * r + 0.7152 * g + 0.0722 * b;
  };
  const behind = (element) => {
    const layers = [];
    for (let e = element; e; e = e.parentElement) {
      const style = getComputedStyle(e);
      if (style.backgroundImage !== "none" || e.tagName === "VIDEO" || e.tagName === "IMG") return null;
      const colour = parse(style.backgroundColor);
      if (colour && colour[3] > 0) {
        layers.push(colour);
        if (colour[3] >= 1) break;
      }
    }
    return layers.reverse().reduce((below, layer) => over(layer, below), [255, 255, 255, 1]);
  };
  const failures = [];
  const judged = new Set();
  const walker = document.createTreeWalker(document.body, NodeFilter.SHOW_TEXT);
  while (walker.nextNode()) {
    const element = walker.currentNode.parentElement;
    if (!walker.currentNode.textContent.trim() || judged.has(element)) continue;
    judged.add(element);
    if (element.closest("script, style, option, [hidden], .visually-hidden, .skip-link, :disabled")) continue;
    const style = getComputedStyle(element);
    const box = element.getBoundingClientRect();
    if (style.visibility === "hidden" || !box.width || !box.height) continue;
    const background = behind(element);
    if (!background) continue;
    const text = over(parse(style.color), background);
    const [light, dark] = [luminance(text), luminance(background)].sort((a, b) => b - a);
    const ratio = (light + 0.05) / (dark + 0.05);
    const size = parseFloat(style.fontSize);
    const large = size >= 24 || (size >= 18.66 && Number(style.fontWeight) >= 700);
    if (ratio < (large ? 3 : 4.5)) {
      const words = walker.currentNode.textContent.trim().slice(0, 40);
      failures.push(`${element.tagName.toLowerCase()}.${element.className} "${words}": `
        + `${ratio.toFixed(2)}:1, ${style.color} on rgb(${background.slice(0, 3).map(Math.round)})`);
    }
  }
  return failures;
};

// How much wider than the window the page is, and the innermost elements that stick out.
window.pitlaneOverflow =
() => {
  const limit = window.innerWidth + 1;
  const out = (e) => e.getBoundingClientRect().right > limit && !e.closest(".table-wrap");
  const culprits = [...document.body.querySelectorAll("*")]
    .filter((e) => out(e) && ![...e.children].some(out))
    .slice(0, 3).map((e) => `${e.tagName.toLowerCase()}.${e.className}`);
  return [document.documentElement.scrollWidth - window.innerWidth, culprits];
};
