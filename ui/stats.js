// The statistics page: /v1/stats as charts (stored against raw bytes by library and by
// codec, takes per codec) and every take's ratio against its error bound.

import { json } from './api.js';
import { el, fmt, svg } from './dom.js';

const bytes = (b) => {
  const u = ['B', 'KB', 'MB', 'GB', 'TB'];
  let i = 0;
  while (b >= 1000 && i < u.length - 1) { b /= 1000; i += 1; }
  return `${b.toFixed(b < 10 && i ? 1 : 0)} ${u[i]}`;
};

/** Horizontal bars, one row per key, one bar per series; a log scale when values span decades. */
function bars(title, rows, series) {
  const W = 720, row = 16 * series.length + 12, L = 150, R = 90, T = 8;
  const H = T + rows.length * row + 24;
  const all = rows.flatMap((r) => series.map((s) => r.values[s.key])).filter((v) => v > 0);
  const max = Math.max(...all, 1);
  const min = Math.min(...all, max);
  const log = max / Math.max(min, 1e-9) > 100;
  const x = (v) => {
    if (v <= 0) return 0;
    return log ? ((W - L - R) * Math.log10(v / (min / 2))) / Math.log10(max / (min / 2)) : ((W - L - R) * v) / max;
  };
  const s = svg('svg', { viewBox: `0 0 ${W} ${H}`, role: 'img', 'aria-label': title, class: 'bars' });
  rows.forEach((r, i) => {
    const y0 = T + i * row;
    s.append(svg('text', { x: L - 6, y: y0 + row / 2 + 4, 'text-anchor': 'end', 'font-size': 12 }, r.label));
    series.forEach((ser, k) => {
      const v = r.values[ser.key];
      const y = y0 + 6 + k * 16;
      s.append(svg('rect', { x: L, y, width: Math.max(1, x(v)), height: 13, fill: ser.color, class: ser.key }));
      s.append(svg('text', { x: L + x(v) + 4, y: y + 11, 'font-size': 11, fill: '#445' }, ser.format(v)));
    });
  });
  const legend = series.map((ser) => ser.label).join(', ') + (log ? ' (log scale)' : '');
  s.append(svg('text', { x: L, y: H - 6, 'font-size': 11, fill: '#667' }, legend));
  return el('figure', {}, el('figcaption', {}, title), s);
}

/** One dot per take: its ratio (log) against its max bound (log). */
function scatter(takes) {
  const W = 720, H = 320, L = 56, R = 12, T = 10, B = 40;
  const pts = takes.filter((t) => t.ratio > 0 && t.max_bound_mm > 0 && t.max_bound_mm < 1e5);
  const s = svg('svg', { viewBox: `0 0 ${W} ${H}`, role: 'img', class: 'scatter',
    'aria-label': `Compression ratio against error bound, ${pts.length} takes` });
  if (!pts.length) return el('figure', {}, el('figcaption', {}, 'Ratio against error bound'), el('p', { class: 'muted' }, 'No takes yet.'));
  const lx = pts.map((t) => Math.log10(t.max_bound_mm));
  const ly = pts.map((t) => Math.log10(t.ratio));
  const [x0, x1] = [Math.min(...lx) - 0.2, Math.max(...lx) + 0.2];
  const [y0, y1] = [Math.min(...ly, 0) - 0.1, Math.max(...ly) + 0.1];
  const X = (v) => L + ((W - L - R) * (v - x0)) / (x1 - x0);
  const Y = (v) => T + (H - T - B) * (1 - (v - y0) / (y1 - y0));
  s.append(svg('rect', { x: L, y: T, width: W - L - R, height: H - T - B, fill: '#fff', stroke: '#d5d9de' }));
  for (let d = Math.ceil(x0); d <= x1; d++) s.append(svg('text', { x: X(d), y: H - B + 14, 'text-anchor': 'middle', 'font-size': 11 }, `${10 ** d} mm`));
  for (let d = Math.ceil(y0); d <= y1; d++) s.append(svg('text', { x: L - 4, y: Y(d) + 4, 'text-anchor': 'end', 'font-size': 11 }, `${10 ** d}×`));
  pts.forEach((t, i) => {
    const c = svg('circle', { cx: X(lx[i]), cy: Y(ly[i]), r: 4, fill: '#1f5fbf', 'fill-opacity': 0.6, class: 'take' });
    c.append(svg('title', {}, `${t.name}: ${fmt.num(t.ratio, 1)}× at max ${t.max_bound_mm} mm (${t.codec})`));
    s.append(c);
  });
  s.append(svg('text', { x: (L + W - R) / 2, y: H - 8, 'text-anchor': 'middle', 'font-size': 11, fill: '#667' }, 'max error bound (log) → compression ratio (log), one dot per take'));
  return el('figure', {}, el('figcaption', {}, 'Ratio against error bound'), s);
}

/** Up to `cap` takes, page by page. */
async function allTakes(cap) {
  const out = [];
  let cursor = null;
  do {
    const q = new URLSearchParams({ limit: '500' });
    if (cursor) q.set('cursor', cursor);
    const page = await json(`/v1/takes?${q}`);
    out.push(...page.items);
    cursor = page.next_cursor;
  } while (cursor && out.length < cap);
  return out;
}

export async function statsPage(main) {
  const [stats, takes] = await Promise.all([json('/v1/stats'), allTakes(5000)]);
  const t = stats.total;
  const sizes = [
    { key: 'raw_bytes', label: 'raw f32', color: '#c9ced6', format: bytes },
    { key: 'stored_bytes', label: 'stored', color: '#1f5fbf', format: bytes },
  ];
  const rows = (m) => Object.entries(m).map(([k, v]) => ({ label: k || '(no library)', values: v }));
  main.append(
    el('h1', {}, 'Statistics'),
    el('p', {}, `${t.takes} takes, ${fmt.num(t.hours, 2)} hours, ${bytes(t.stored_bytes)} stored for ${bytes(t.raw_bytes)} raw: ratio ${fmt.num(t.ratio, 1)}; largest error ${fmt.num(t.max_mm, 3)} mm (p95 of takes ${fmt.num(t.max_mm_p95, 3)} mm).`),
    el('p', { class: 'split' }, `Points: ${bytes(t.points?.stored_bytes ?? 0)} stored for ${bytes(t.points?.raw_bytes ?? 0)} raw (ratio ${fmt.num(t.points?.ratio ?? 0, 1)}). `,
      `Analog channels: ${bytes(t.analog?.stored_bytes ?? 0)} stored for ${bytes(t.analog?.raw_bytes ?? 0)} raw as the files held them (ratio ${fmt.num(t.analog?.ratio ?? 0, 1)}). `,
      `C3D parameters: ${bytes(t.parameters_bytes ?? 0)}.`),
    el('div', { class: 'charts' },
      bars('Stored against raw, by library', rows(stats.by_library), sizes),
      bars('Stored against raw, by codec', rows(stats.by_codec), sizes),
      bars('Takes per codec', rows(stats.by_codec), [{ key: 'takes', label: 'takes', color: '#2e8b57', format: String }]),
      scatter(takes),
    ),
  );
  return null;
}
