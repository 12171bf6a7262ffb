// The compare page: two or more takes (or one take stored at two bounds) in step on one
// clock, overlaid in one view or side by side; the URL keeps the takes, the view, the
// playhead, speed and loop, so it can be shared. Takes of the same points are also compared
// frame by frame: the largest and mean distance of each to the first, in mm.
//
// `starts=` (seconds, one per take) plays each take from its own time and `span=` ends the
// clock after that many seconds: how a search's results play beside their query, which may
// be another range of the same take.

import { json } from './api.js';
import { el, fmt } from './dom.js';
import { showError } from './app.js';
import { shapeOf, TakeFrames } from './frames.js';
import { COLOURS, Player } from './player.js';
import { Transport } from './transport.js';

/** Takes on one page at most: one colour each. */
const MAX_TAKES = COLOURS.length;

export async function comparePage(main, params) {
  const { ids, starts } = entries(params);
  const span = Number(params.get('span')) > 0 ? Number(params.get('span')) : null;
  const mode = params.get('mode') === 'side' ? 'side' : 'overlay';
  const records = new Map(await Promise.all([...new Set(ids)].map(async (id) => [id, await json(`/v1/takes/${encodeURIComponent(id)}`)])));
  const takes = ids.map((id) => records.get(id));
  const shapes = await Promise.all(takes.map(shapeOf));
  let transport = null;
  const url = (changes = {}, q = transport ? transport.query() : params) => {
    const next = { ids: ids.join(','), mode, ...changes };
    const all = new URLSearchParams(q);
    for (const [k, v] of Object.entries(next)) all.set(k, v);
    // Each take keeps its start (a take added starts at 0, `changes.starts`), and the
    // clock its span.
    if (!('starts' in changes)) {
      if (starts.some((s) => s > 0)) all.set('starts', starts.join(','));
      else all.delete('starts');
    }
    if (span) all.set('span', String(span));
    return `#/compare?${all}`;
  };

  main.append(el('h1', {}, 'Compare'));
  main.append(await picker(takes, (id) => { location.hash = url({ ids: [...ids, id].join(','), starts: [...starts, 0].join(',') }); }));
  if (takes.length === 0) {
    main.append(el('p', { class: 'muted' }, 'Choose takes to compare: the same take stored at two bounds, or any takes.'));
    return () => {};
  }

  const modes = el('div', { class: 'controls', role: 'radiogroup', 'aria-label': 'view' },
    ...['overlay', 'side'].map((m) => el('label', {}, el('input', {
      type: 'radio', name: 'mode', value: m, checked: m === mode ? '' : null,
      onchange: () => { location.hash = url({ mode: m }); },
    }), m === 'overlay' ? ' overlaid' : ' side by side')));
  const legend = el('table', { class: 'legend' },
    el('thead', {}, el('tr', {}, ...['', 'take', 'codec', 'bound mm', 'max / mean error mm', 'ratio', 'now', ''].map((h) => el('th', { scope: 'col' }, h)))),
    el('tbody', {}, ...takes.map((t, i) => el('tr', {},
      el('td', {}, el('span', { class: 'swatch', style: { background: COLOURS[i] }, 'aria-label': `colour ${i + 1}` })),
      el('td', {}, el('a', { href: `#/take/${encodeURIComponent(t.id)}` }, t.name || t.id), ' ', el('small', { class: 'muted' }, t.library || ''),
        starts[i] > 0 ? el('small', { class: 'muted' }, ` from ${fmt.num(starts[i], 2)} s`) : null),
      el('td', {}, t.codec),
      el('td', { class: 'n' }, String(t.max_bound_mm)),
      el('td', { class: 'n' }, `${fmt.num(t.max_mm, 3)} / ${fmt.num(t.mean_mm, 3)}`),
      el('td', { class: 'n' }, fmt.num(t.ratio, 1)),
      el('td', { class: 'n now' }, '—'),
      el('td', {}, el('button', { 'aria-label': `remove ${t.name || t.id}`, onclick: () => {
        location.hash = url({ ids: ids.filter((_, j) => j !== i).join(','), starts: starts.filter((_, j) => j !== i).join(',') });
      } }, '✕')),
    ))));

  // One view with every figure, or one view per take.
  const abort = new AbortController();
  const views = mode === 'overlay' ? [null] : takes;
  const canvases = views.map((t) => el('canvas', { class: 'view', tabindex: '0', 'aria-label': t ? `3-D view of ${t.name || t.id}` : 'the takes overlaid in 3-D' }));
  const players = canvases.map((c) => new Player(c));
  const figures = shapes.map((s, i) => players[mode === 'overlay' ? 0 : i].add(s, COLOURS[i]));
  if (mode === 'side') linkCameras(players);
  const sources = takes.map((t) => new TakeFrames(t, abort.signal));
  const same = takes.every((t) => t.layout === takes[0].layout);
  const framed = players.map(() => false);

  async function show(t) {
    const f = sources.map((s, i) => s.frameAt(starts[i] + t));
    const xyz = await Promise.all(f.map((g, i) => sources[i].at(g)));
    // A later seek may have moved the playhead while these frames were fetched.
    if (sources.some((s, i) => s.frameAt(starts[i] + transport.t) !== f[i])) return;
    // Each view's camera is pointed once any of its points is present (a capture may start
    // with none).
    players.forEach((p, k) => {
      if (!framed[k]) framed[k] = p.frame(figures.map((fig, i) => [fig, xyz[i]]).filter(([fig]) => fig.player === p));
    });
    figures.forEach((fig, i) => fig.set(xyz[i]));
    players.forEach((p) => p.draw());
    canvases[0].dataset.frames = f.join(',');
    const now = legend.querySelectorAll('td.now');
    f.forEach((g, i) => {
      let text = `frame ${g}`;
      if (same && i > 0) {
        const d = distance(xyz[0], xyz[i], takes[0].metres_per_unit * 1000, takes[i].metres_per_unit * 1000);
        if (d) text += `; to the first: max ${d.max.toFixed(2)}, mean ${d.mean.toFixed(2)} mm`;
      }
      now[i].textContent = text;
    });
    sources.forEach((s, i) => s.prefetch(f[i]));
  }

  transport = new Transport({
    last: span ?? Math.max(...takes.map((t, i) => Math.max(0, t.frames - 1) / t.fps - starts[i])),
    rate: Math.max(...takes.map((t) => t.fps)),
    params,
    onSeek: show,
    onShare: () => history.replaceState(null, '', url()),
    onError: showError,
  });
  main.append(
    modes,
    el('div', { class: mode === 'side' ? 'views side' : 'views' }, ...canvases),
    transport.bar,
    transport.loopBar,
    el('div', { class: 'scroll' }, legend),
    transport.help,
  );
  await transport.seek(transport.t);
  return () => {
    transport.dispose();
    abort.abort();
    players.forEach((p) => p.dispose());
  };
}

/**
 * The takes the URL names, each with the second it plays from: a take may come twice when
 * its starts differ (a range found beside its query), never twice at one start.
 */
function entries(params) {
  const ids = (params.get('ids') ?? '').split(',');
  const given = (params.get('starts') ?? '').split(',').map(Number);
  const seen = new Set();
  const out = { ids: [], starts: [] };
  ids.forEach((id, i) => {
    const start = Number.isFinite(given[i]) && given[i] > 0 ? given[i] : 0;
    const key = `${id}@${start}`;
    if (!id || seen.has(key) || out.ids.length >= MAX_TAKES) return;
    seen.add(key);
    out.ids.push(id);
    out.starts.push(start);
  });
  return out;
}

/** A chooser of a take to add: takes of the first take's layout first. */
async function picker(takes, add) {
  const select = el('select', { 'aria-label': 'take to add' });
  const button = el('button', { type: 'submit' }, 'Add');
  const form = el('form', { class: 'controls' }, el('label', {}, 'add a take ', select), button);
  if (takes.length >= MAX_TAKES) {
    button.disabled = true;
    select.disabled = true;
  }
  const shown = new Set(takes.map((t) => t.id));
  const layout = takes[0]?.layout;
  const lists = await Promise.all([
    layout ? json(`/v1/takes?limit=100&layout=${encodeURIComponent(layout)}`) : { items: [] },
    json('/v1/takes?limit=100'),
  ]);
  const seen = new Set();
  for (const [label, list] of [['same points', lists[0]], ['all takes', lists[1]]]) {
    const items = list.items.filter((t) => !shown.has(t.id) && !seen.has(t.id) && !t.live);
    if (!items.length) continue;
    select.append(el('optgroup', { label }, ...items.map((t) => {
      seen.add(t.id);
      return el('option', { value: t.id }, `${t.name || t.id} — ${t.codec}, max ${t.max_bound_mm} mm`);
    })));
  }
  if (!seen.size) {
    select.append(el('option', { value: '' }, 'no other takes'));
    button.disabled = true;
  }
  form.addEventListener('submit', (e) => {
    e.preventDefault();
    if (select.value) add(select.value);
  });
  return form;
}

/** Orbiting one view turns the others the same way, each about its own figure. */
function linkCameras(players) {
  players.forEach((p) => p.controls.addEventListener('change', () => {
    const offset = p.camera.position.clone().sub(p.controls.target);
    for (const q of players) {
      if (q === p) continue;
      q.camera.position.copy(q.controls.target).add(offset);
      q.camera.lookAt(q.controls.target);
      q.draw();
    }
  }));
}

/** The largest and mean distance between two frames of the same points, mm (both present). */
function distance(a, b, mmA, mmB) {
  let max = 0;
  let sum = 0;
  let n = 0;
  for (let p = 0; p + 2 < a.length; p += 3) {
    const dx = a[p] * mmA - b[p] * mmB;
    const dy = a[p + 1] * mmA - b[p + 1] * mmB;
    const dz = a[p + 2] * mmA - b[p + 2] * mmB;
    const d = Math.hypot(dx, dy, dz);
    if (Number.isFinite(d)) {
      max = Math.max(max, d);
      sum += d;
      n += 1;
    }
  }
  return n ? { max, mean: sum / n } : null;
}
