// The take page: the figure in 3-D with play/pause, speed, a scrubber and a loop range;
// frames fetched one second at a time as the playhead moves (so an hour-long take opens as
// fast as a short one); the take's numbers, its codec decision, and downloads of the range.

import { download, frames as fetchFrames, json } from './api.js';
import { el, fmt, svg } from './dom.js';
import { showError } from './app.js';
import { Player } from './player.js';

const SPEEDS = [0.1, 0.25, 0.5, 1, 2, 4];
/** Seconds of frames kept in memory at most. */
const KEPT_WINDOWS = 120;

export async function takePage(main, id, params) {
  const take = await json(`/v1/sequences/${encodeURIComponent(id)}`);
  let bones = [];
  if (take.skeleton) {
    const sk = await json(`/v1/skeletons/${encodeURIComponent(take.skeleton)}`);
    if (sk.hierarchy?.length === take.points) {
      sk.hierarchy.forEach((j, i) => { if (j.parent !== null && j.parent !== undefined) bones.push([j.parent, i]); });
    }
  }
  const fps = take.fps;
  const total = take.frames;
  const window = Math.max(1, Math.round(fps));

  // --- layout
  const canvas = el('canvas', { class: 'view', 'aria-label': `3-D view of ${take.name}`, tabindex: '0' });
  const play = el('button', { class: 'play', 'aria-label': 'play' }, '▶');
  const speed = el('select', { 'aria-label': 'speed' }, ...SPEEDS.map((s) => el('option', { value: String(s) }, `${s}×`)));
  speed.value = params.get('speed') ?? '1';
  const scrub = el('input', { type: 'range', min: '0', max: String(Math.max(0, total - 1)), step: '1', value: '0', 'aria-label': 'playhead (frame)' });
  const clock = el('output', { class: 'clock' }, '0.00 s');
  const from = el('input', { type: 'number', min: '0', step: '0.1', value: params.get('from') ?? '0', 'aria-label': 'loop from (s)' });
  const to = el('input', { type: 'number', min: '0', step: '0.1', value: params.get('to') ?? (total / fps).toFixed(2), 'aria-label': 'loop to (s)' });
  const loop = el('input', { type: 'checkbox', 'aria-label': 'loop' });
  loop.checked = params.get('loop') === '1';
  const fetched = el('span', { class: 'muted' });
  const chart = el('div', { class: 'chart' });
  main.append(
    el('h1', {}, take.name || take.id, ' ', el('small', { class: 'muted' }, take.library ? `in ${take.library}` : '')),
    canvas,
    el('div', { class: 'controls' }, play, speed, scrub, clock),
    chart,
    el('div', { class: 'controls' },
      el('label', {}, 'loop ', loop), el('label', {}, 'from ', from, ' s'), el('label', {}, 'to ', to, ' s'), fetched),
    el('p', { class: 'muted' }, 'Keys: space play/pause, ←/→ one frame (shift: one second), Home/End.'),
  );

  // --- frames, one window (a second) at a time
  const windows = new Map(); // index -> Promise<Float32Array>
  let fetchCount = 0;
  const abort = new AbortController();
  function windowOf(index) {
    let w = windows.get(index);
    if (!w) {
      const start = index * window;
      const end = Math.min(total, start + window);
      fetchCount += 1;
      fetched.textContent = ` ${fetchCount} ranges fetched`;
      w = fetchFrames(id, start, end, abort.signal).then((r) => r.data);
      w.catch(() => windows.delete(index));
      windows.set(index, w);
      if (windows.size > KEPT_WINDOWS) windows.delete(windows.keys().next().value);
    }
    return w;
  }
  const ready = new Map(); // index -> Float32Array, once loaded
  async function frameData(f) {
    const index = Math.floor(f / window);
    let data = ready.get(index);
    if (!data) {
      data = await windowOf(index);
      ready.set(index, data);
      if (ready.size > KEPT_WINDOWS) ready.delete(ready.keys().next().value);
    }
    const n = take.points * 3;
    const k = f - index * window;
    return data.subarray(k * n, (k + 1) * n);
  }

  const player = new Player(canvas, { points: take.points, bones, metres: take.metres_per_unit });
  let current = Math.min(total - 1, Math.max(0, Math.round(Number(params.get('t') ?? 0) * fps)));
  let playing = false;
  let last = 0;
  let shownFrame = -1;
  let raf = 0;

  let moveMarker = () => {};
  async function show(f) {
    const g = Math.min(total - 1, Math.max(0, Math.floor(f)));
    current = g;
    moveMarker(g);
    scrub.value = String(g);
    clock.textContent = `${(g / fps).toFixed(2)} s`;
    const xyz = await frameData(g);
    // A later call may have moved the playhead while this frame's second was fetched.
    if (current !== g) return;
    if (shownFrame < 0) player.frame(xyz);
    shownFrame = g;
    player.show(xyz);
    canvas.dataset.frame = String(g);
    // Fetch the next second before the playhead needs it.
    const next = Math.floor(g / window) + 1;
    if (next * window < total) windowOf(next);
  }

  function range() {
    const a = Math.max(0, Math.floor(Number(from.value) * fps));
    const b = Math.min(total, Math.ceil(Number(to.value) * fps));
    return b > a ? [a, b] : [0, total];
  }

  function share() {
    const q = new URLSearchParams({ t: (current / fps).toFixed(2), speed: speed.value });
    if (loop.checked) { q.set('loop', '1'); q.set('from', from.value); q.set('to', to.value); }
    history.replaceState(null, '', `#/take/${encodeURIComponent(id)}?${q}`);
  }

  // Playback keeps its own clock (seconds into the take): frames are whole, time is not.
  let clockT = 0;
  function tick(now) {
    if (!playing) return;
    const dt = last ? (now - last) / 1000 : 0;
    last = now;
    clockT += dt * Number(speed.value);
    let f = Math.floor(clockT * fps);
    const [a, b] = loop.checked ? range() : [0, total];
    if (f >= b || f < a) {
      if (loop.checked) {
        f = a;
        clockT = a / fps;
      } else {
        f = total - 1;
        setPlaying(false);
      }
    }
    if (f !== shownFrame) show(f).catch(showError);
    raf = requestAnimationFrame(tick);
  }

  function setPlaying(on, keepUrl = false) {
    playing = on;
    play.textContent = on ? '❚❚' : '▶';
    play.setAttribute('aria-label', on ? 'pause' : 'play');
    last = 0;
    if (on) {
      clockT = current / fps;
      raf = requestAnimationFrame(tick);
    } else {
      cancelAnimationFrame(raf);
      if (!keepUrl) share();
    }
  }

  play.addEventListener('click', () => setPlaying(!playing));
  speed.addEventListener('change', share);
  loop.addEventListener('change', share);
  scrub.addEventListener('input', () => show(Number(scrub.value)).then(share).catch(showError));
  function onKey(e) {
    if (e.target instanceof HTMLInputElement && e.target.type !== 'range') return;
    const step = e.shiftKey ? window : 1;
    if (e.key === ' ') { e.preventDefault(); setPlaying(!playing); }
    else if (e.key === 'ArrowRight') { e.preventDefault(); show(current + step).then(share).catch(showError); }
    else if (e.key === 'ArrowLeft') { e.preventDefault(); show(current - step).then(share).catch(showError); }
    else if (e.key === 'Home') { e.preventDefault(); show(0).then(share).catch(showError); }
    else if (e.key === 'End') { e.preventDefault(); show(total - 1).then(share).catch(showError); }
  }
  document.addEventListener('keydown', onKey);

  // --- numbers, decision, downloads
  const facts = [
    ['id', take.id], ['library', take.library || '—'], ['tags', (take.tags || []).join(', ') || '—'],
    ['source format', take.source_format], ['frames', `${total} at ${fmt.num(fps, 3)} fps (${fmt.secs(take.duration_s)})`],
    ['points', String(take.points)], ['codec', take.codec], ['ratio', fmt.num(take.ratio, 1)],
    ['bound', `max ${take.max_bound_mm} mm${take.mean_bound_mm ? `, mean ${take.mean_bound_mm} mm` : ''}`],
    ['max / mean error', `${fmt.num(take.max_mm, 3)} / ${fmt.num(take.mean_mm, 3)} mm`],
    ['stored', `${take.stored_bytes} bytes of ${take.raw_bytes} raw`],
  ];
  main.append(el('h2', {}, 'Take'), el('div', { class: 'scroll' }, el('table', { class: 'facts' }, el('tbody', {}, ...facts.map(([k, v]) => el('tr', {}, el('th', { scope: 'row' }, k), el('td', {}, v)))))));
  const d = take.meta?.decision;
  if (d) {
    main.append(
      el('h2', {}, 'Codec decision'),
      el('p', { class: 'reason' }, d.reason),
      el('div', { class: 'scroll' }, el('table', { class: 'decision' },
        el('thead', {}, el('tr', {}, ...['codec', 'stored bytes', 'max mm', 'mean mm', 'encode ms', ''].map((h) => el('th', { scope: 'col' }, h)))),
        el('tbody', {},
          ...(d.tried || []).map((c) => el('tr', { class: c.codec === d.winner ? 'winner' : '' },
            el('td', {}, c.codec), el('td', { class: 'n' }, String(c.stored_bytes)),
            el('td', { class: 'n' }, fmt.num(c.max_mm, 3)), el('td', { class: 'n' }, fmt.num(c.mean_mm, 3)),
            el('td', { class: 'n' }, fmt.num(c.encode_ms, 1)), el('td', {}, c.codec === d.winner ? 'winner' : ''))),
          ...(d.skipped || []).map((s) => el('tr', { class: 'skipped' },
            el('td', {}, s.codec ?? String(s)), el('td', { colspan: '5' }, s.reason ?? 'skipped'))),
        ))),
    );
  }
  const formats = ['json', 'csv', 'trc', 'npy', 'f32'];
  if (take.source_format === 'bvh') formats.unshift('bvh');
  main.append(el('h2', {}, 'Download'), el('p', {}, 'The loop range (or the whole take): ',
    ...formats.map((f) => el('button', { class: 'download', onclick: () => {
      const [a, b] = loop.checked ? range() : [0, total];
      download(`/v1/sequences/${encodeURIComponent(id)}/frames?start=${a}&end=${b}&format=${f}`, `${take.name || take.id}_${a}-${b}.${f}`).catch(showError);
    } }, f.toUpperCase()))));

  // --- what compression did: the error second by second against the bound
  try {
    const e = await json(`/v1/sequences/${encodeURIComponent(id)}/errors`);
    moveMarker = errorChart(chart, e, total, (f) => show(f).then(share).catch(showError));
  } catch (err) {
    chart.replaceChildren(el('p', { class: 'muted' }, `No error chart: ${err.message}`));
  }

  await show(current);
  // Leaving the page: stop, without writing this take's URL over the one navigated to.
  return () => {
    setPlaying(false, true);
    abort.abort();
    document.removeEventListener('keydown', onKey);
    player.dispose();
  };
}

/**
 * The largest and mean error per second as lines over the take, the bound as a dashed line,
 * and a marker at the playhead; a click seeks there. Returns the marker's mover.
 */
function errorChart(box, e, total, seek) {
  const W = 1000, H = 160, L = 48, R = 8, T = 10, B = 22;
  const bins = e.max_mm.length;
  const top = Math.max(e.max_bound_mm, ...e.max_mm, 1e-6) * 1.1;
  const x = (f) => L + ((W - L - R) * f) / Math.max(1, total - 1);
  const y = (mm) => T + (H - T - B) * (1 - mm / top);
  const line = (values) => values.map((v, i) => `${x((i + 0.5) * e.frames_per_bin).toFixed(1)},${y(v).toFixed(1)}`).join(' ');
  const s = svg('svg', { viewBox: `0 0 ${W} ${H}`, class: 'errors', role: 'img',
    'aria-label': `Error per second: largest up to ${Math.max(...e.max_mm).toFixed(3)} mm, bound ${e.max_bound_mm} mm` });
  s.append(svg('rect', { x: L, y: T, width: W - L - R, height: H - T - B, fill: '#fff', stroke: '#d5d9de' }));
  for (const mm of [0, top / 2 / 1.1, e.max_bound_mm]) {
    const t = svg('text', { x: L - 4, y: y(mm) + 4, 'text-anchor': 'end', 'font-size': 11, fill: '#667' });
    t.textContent = mm.toFixed(mm < 1 ? 2 : 1);
    s.append(t);
  }
  s.append(svg('line', { x1: L, x2: W - R, y1: y(e.max_bound_mm), y2: y(e.max_bound_mm), stroke: '#c0392b', 'stroke-dasharray': '6 4', class: 'bound' }));
  if (e.mean_bound_mm) {
    s.append(svg('line', { x1: L, x2: W - R, y1: y(e.mean_bound_mm), y2: y(e.mean_bound_mm), stroke: '#1f5fbf', 'stroke-dasharray': '2 4' }));
  }
  if (bins) {
    s.append(svg('polyline', { points: line(e.max_mm), fill: 'none', stroke: '#c0392b', 'stroke-width': 1.5, class: 'max' }));
    s.append(svg('polyline', { points: line(e.mean_mm), fill: 'none', stroke: '#1f5fbf', 'stroke-width': 1.5, class: 'mean' }));
  }
  const marker = svg('line', { y1: T, y2: H - B, stroke: '#1d2430', 'stroke-width': 1.5 });
  s.append(marker);
  const label = svg('text', { x: W - R, y: H - 6, 'text-anchor': 'end', 'font-size': 11, fill: '#667' });
  label.textContent = 'error per second (mm): largest — red, mean — blue; dashed: bound';
  s.append(label);
  s.addEventListener('click', (ev) => {
    const r = s.getBoundingClientRect();
    const fx = ((ev.clientX - r.left) / r.width) * W;
    seek(Math.round(((fx - L) / (W - L - R)) * (total - 1)));
  });
  box.replaceChildren(s);
  return (f) => {
    marker.setAttribute('x1', x(f));
    marker.setAttribute('x2', x(f));
  };
}
