// Small DOM helpers every page uses: HTML and SVG elements from attributes and children,
// and number formats.

/**
 * An HTML element; `on…` attributes become listeners, null/undefined/false ones are left out.
 * `style` is an object of properties, set through the element's style (the page's
 * Content-Security-Policy refuses style attributes, not styles set from script).
 */
export function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === null || v === undefined || v === false) continue;
    if (k === 'class') e.className = v;
    else if (k === 'style') Object.assign(e.style, v);
    else if (k.startsWith('on')) e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v);
  }
  e.append(...children.filter((c) => c !== null && c !== undefined));
  return e;
}

const SVG = 'http://www.w3.org/2000/svg';

/** An SVG element, with `text` as its content when given. */
export function svg(tag, attrs = {}, text) {
  const e = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  if (text !== undefined) e.textContent = text;
  return e;
}

export const fmt = {
  num: (v, d = 1) => (Number.isFinite(v) ? v.toFixed(d) : '—'),
  secs: (s) => (s >= 60 ? `${Math.floor(s / 60)} min ${Math.round(s % 60)} s` : `${s.toFixed(1)} s`),
  /** A take's labels as `key: value, …` (what the library's labels filter reads back). */
  labels: (l) => Object.entries(l || {}).map(([k, v]) => `${k}: ${v}`).join(', '),
};
