// The take page: the figure in 3-D with play/pause, speed, a scrubber and a loop range;
// frames fetched one second at a time as the playhead moves (so an hour-long take opens as
// fast as a short one); the take's numbers, its codec decision, and downloads of the range.

import { download, json, request } from './api.js';
import { el, fmt, svg } from './dom.js';
import { showError } from './app.js';
import { shapeOf, TakeFrames } from './frames.js';
import { Player, GltfFigure } from './player.js';
import { similarPanel } from './similar.js';
import { Transport } from './transport.js';

export async function takePage(main, id, params) {
  const take = await json(`/v1/takes/${encodeURIComponent(id)}`);
  if (take.live) {
    // Still recording: the live page shows it as it arrives.
    location.replace(`#/live/${encodeURIComponent(id)}`);
    return () => {};
  }
  const shape = await shapeOf(take);
  const fps = take.fps;
  const total = take.frames;

  const canvas = el('canvas', { class: 'view', 'aria-label': `3-D view of ${take.name}`, tabindex: '0' });
  const fetched = el('span', { class: 'muted' });
  const chart = el('div', { class: 'chart' });
  const abort = new AbortController();
  const frames = new TakeFrames(take, abort.signal, () => {
    fetched.textContent = ` ${frames.fetches} ranges fetched`;
  });
  const player = new Player(canvas);
  const figure = player.add(shape);
  let framed = false;
  let moveMarker = () => {};

  let glb = null;
  async function show(t) {
    glb?.at(t);
    const f = frames.frameAt(t);
    moveMarker(f);
    const xyz = await frames.at(f);
    // A later seek may have moved the playhead while this frame's second was fetched.
    if (frames.frameAt(transport.t) !== f) return;
    // The camera is pointed at the first frame with a point present (a capture may start
    // with every marker missing).
    if (!framed) framed = player.frame([[figure, xyz]]);
    figure.show(xyz);
    // Where the head and the lower ankle stand in the view (metres, +Y up), for anyone
    // checking that the figure stands up (the browser test does).
    const head = figure.centroid(shape.head);
    const feet = shape.feet.map((p) => figure.centroid([p])).filter(Boolean);
    canvas.dataset.head = head ? head.y.toFixed(4) : '';
    canvas.dataset.feet = feet.length ? Math.min(...feet.map((v) => v.y)).toFixed(4) : '';
    // Time to first frame, for anyone measuring the page (performance.getEntriesByName).
    if (!canvas.dataset.frame) performance.mark('mocapstore:first-frame');
    canvas.dataset.frame = String(f);
    frames.prefetch(f);
  }
  const transport = new Transport({
    last: Math.max(0, total - 1) / fps,
    rate: fps,
    params,
    onSeek: show,
    onShare: () => history.replaceState(null, '', `#/take/${encodeURIComponent(id)}?${transport.query()}`),
    onError: showError,
  });
  transport.loopBar.append(fetched);
  // Point names over the figure (marker labels, joint names), on demand.
  const labelBox = el('div', { class: 'labels', 'aria-hidden': 'true' });
  const names = take.meta?.point_names ?? [];
  const labels = el('input', { type: 'checkbox', class: 'labels-toggle', disabled: names.length ? null : '' });
  labels.addEventListener('change', () => figure.label(labels.checked ? names : null, labelBox));
  transport.loopBar.prepend(el('label', {}, 'point names ', labels));
  // The camera walks along with the pelvis, when the body names one.
  const follow = el('input', { type: 'checkbox', class: 'follow-toggle', disabled: shape.pelvis.length && shape.up ? null : '' });
  follow.addEventListener('change', () => player.followFigure(follow.checked ? figure : null));
  transport.loopBar.prepend(el('label', { title: 'keep the camera on the pelvis as the body moves' }, 'follow ', follow));
  canvas.dataset.up = shape.up ?? 'unknown';
  const compare = el('a', { href: `#/compare?ids=${encodeURIComponent(id)}` }, 'compare with another take');
  main.append(
    el('h1', {}, take.name || take.id, ' ', el('small', { class: 'muted' }, take.library ? `in ${take.library}` : '')),
    el('div', { class: 'stage' }, canvas, labelBox),
    transport.bar,
    chart,
    transport.loopBar,
    el('p', { class: 'muted' }, transport.help.textContent, ' ', compare),
  );
  // The loop range when the loop is on, else the whole take (the panel caps its length).
  main.append(similarPanel(take, () => (transport.loop.checked ? transport.range() : [0, transport.last + 1 / fps])));

  // --- numbers, decision, downloads
  const facts = [
    ['id', take.id], ['library', take.library || '—'], ['tags', (take.tags || []).join(', ') || '—'],
    ['labels', fmt.labels(take.labels) || '—'],
    ['source format', take.source_format], ['frames', `${total} at ${fmt.num(fps, 3)} fps (${fmt.secs(take.duration_s)})`],
    ['points', String(take.points)], ['codec', take.codec], ['ratio', fmt.num(take.ratio, 1)],
    ['bound', `max ${take.max_bound_mm} mm${take.mean_bound_mm ? `, mean ${take.mean_bound_mm} mm` : ''}`],
    ['max / mean error', `${fmt.num(take.max_mm, 3)} / ${fmt.num(take.mean_mm, 3)} mm`],
    ['stored', `${take.stored_bytes} bytes of ${take.raw_bytes} raw`],
  ];
  const analog = take.meta?.analog;
  if (analog) {
    facts.push(
      ['analog channels', `${analog.channels.length} at ${fmt.num(analog.rate, 1)} Hz (${analog.channels.map((c) => c.unit ? `${c.label} ${c.unit}` : c.label).join(', ')})`],
      ['analog codec', `${analog.codec}: ${analog.stored_bytes} bytes of ${analog.raw_bytes} raw (ratio ${fmt.num(analog.ratio, 1)})`],
      ['points alone', `${take.stored_bytes - analog.stored_bytes} bytes of ${take.raw_bytes - analog.raw_bytes} raw, with the file's parameters`],
    );
  }
  const body = take.body;
  if (body) {
    const roles = body.roles ?? {};
    const placed = Object.keys(roles).length;
    facts.push(
      ['up', body.up ? `${body.up} (${body.up_from})` : 'unknown'],
      ['forward', body.forward ? `${body.forward} (${body.forward_from})` : 'unknown'],
      ['floor', body.floor_m === null || body.floor_m === undefined ? '—' : `${fmt.num(body.floor_m, 3)} m along up`],
      ['pelvis (the moving root)', (roles.pelvis ?? []).join(', ') || '—'],
      ['roles', `${placed} of ${placed + (body.unplaced?.length ?? 0)} placed${body.convention ? ` by ${body.convention} names` : ''}${body.given?.length ? `; given: ${body.given.join(', ')}` : ''}`],
    );
  }
  const events = take.meta?.events ?? [];
  if (events.length) facts.push(['events', events.map((e) => `${e.context} ${e.label} ${fmt.num(e.time_s, 2)} s`.trim()).join('; ')]);
  main.append(el('h2', {}, 'Take'), el('div', { class: 'scroll' }, el('table', { class: 'facts' }, el('tbody', {}, ...facts.map(([k, v]) => el('tr', {}, el('th', { scope: 'row' }, k), el('td', {}, v)))))));
  const d = take.meta?.decision;
  if (body) main.append(el('p', { class: `reason body-reason${body.up ? '' : ' warning'}` }, `Body: ${body.reason}`));
  if (analog) main.append(el('p', { class: 'reason analog-reason' }, `Analog: ${analog.reason}`));
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
  /** Seconds [a, b] as frames [start, end). */
  const frameRange = ([a, b]) => [Math.floor(a * fps + 1e-6), Math.min(total, Math.floor(b * fps + 1e-6) + 1)];
  const formats = ['glb', 'gltf', 'c3d', 'json', 'csv', 'trc', 'npy', 'f32'];
  if (take.source_format === 'bvh') formats.unshift('bvh');
  // The transforms every format takes on the way out (glTF is always metres, +Y up).
  const outFps = el('input', { type: 'number', min: '1', max: '10000', step: 'any', placeholder: String(fmt.num(fps, 2)), class: 'out-fps', title: 'frame rate of the file (resampled)', 'aria-label': 'frame rate of the file' });
  const pick = (cls, title, options) => el('select', { class: cls, title },
    ...options.map(([v, label]) => el('option', { value: v }, label)));
  const root = pick('out-root', 'root motion', [['keep', 'root: as captured'], ['in-place', 'root: in place'], ['extract', 'root: extracted']]);
  const up = pick('out-up', 'up axis', [['', 'up: as stored'], ['y', 'up: +Y'], ['z', 'up: +Z'], ['-y', 'up: −Y'], ['-z', 'up: −Z'], ['x', 'up: +X'], ['-x', 'up: −X']]);
  const unit = pick('out-unit', 'unit', [['', 'unit: as stored'], ['mm', 'mm'], ['cm', 'cm'], ['m', 'm'], ['in', 'in']]);
  // The skeleton to put the take on: its own, a standard rig, or a rig uploaded on its own
  // (POST /v1/skeletons; a character's GLB is then the character playing the take).
  const rig = pick('out-rig', 'the skeleton the file puts the take on', [['', 'rig: its own'], ['mixamo', 'rig: Mixamo'], ['smpl', 'rig: SMPL']]);
  rig.setAttribute('aria-label', 'skeleton to put the take on');
  if (take.skeleton) {
    json('/v1/skeletons?layout=uploaded').then((r) => {
      for (const s of r.items || []) {
        const what = s.uploaded_as === 'glb' || s.uploaded_as === 'gltf' ? `${s.uploaded_as} character` : `${s.uploaded_as} rig`;
        rig.append(el('option', { value: s.id }, `rig: ${what} ${s.id.slice(0, 8)} (${s.joints} joints)`));
      }
    }).catch(() => {});
  } else {
    rig.disabled = true;
  }
  // Root motion follows the pelvis along the floor: it needs both.
  if (!(body?.up && body.roles?.pelvis)) root.disabled = true;
  if (!body?.up) up.disabled = true;
  /** The query of the chosen transforms (those that apply to format `f`). */
  const transforms = (f) => {
    const q = [];
    if (outFps.value) q.push(`fps=${encodeURIComponent(outFps.value)}`);
    if (root.value !== 'keep') q.push(`root=${root.value}`);
    if (rig.value && f !== 'c3d') q.push(`skeleton=${encodeURIComponent(rig.value)}`);
    if (f !== 'glb' && f !== 'gltf') {
      if (up.value) q.push(`up=${up.value}`);
      if (unit.value) q.push(`unit=${unit.value}`);
    }
    return q.map((x) => `&${x}`).join('');
  };
  main.append(el('h2', {}, 'Download'), el('p', { class: 'transforms' }, el('label', {}, outFps, ' fps'), ' ', root, up, unit, rig),
    el('p', {}, 'The loop range (or the whole take): ',
    ...formats.map((f) => el('button', { class: 'download', onclick: () => {
      const [a, b] = transport.loop.checked ? frameRange(transport.range()) : [0, total];
      download(`/v1/takes/${encodeURIComponent(id)}/frames?start=${a}&end=${b}&format=${f}${transforms(f)}`, `${take.name || take.id}_${a}-${b}.${f}`).catch(showError);
    } }, f.toUpperCase())),
    el('button', { class: 'open-glb', title: 'load the GLB the server writes (three.js GLTFLoader) beside the figure', onclick: async () => {
      try {
        glb?.dispose();
        const r = await request(`/v1/takes/${encodeURIComponent(id)}/frames?format=glb${transforms('glb')}`);
        glb = await GltfFigure.load(player, await r.arrayBuffer(), 1.0);
        window.mocapstoreGlb = glb; // for tests: the loaded glTF's node positions
        glb.at(transport.t);
      } catch (e) {
        showError(e);
      }
    } }, 'Open GLB beside'),
    ...(analog ? [el('button', { class: 'download analog', onclick: () => {
      const [a, b] = transport.loop.checked ? frameRange(transport.range()) : [0, total];
      download(`/v1/takes/${encodeURIComponent(id)}/analog?start=${a}&end=${b}&format=csv`, `${take.name || take.id}_analog_${a}-${b}.csv`).catch(showError);
    } }, 'ANALOG CSV')] : [])));

  // --- what compression did: the error second by second against the bound
  try {
    const e = await json(`/v1/takes/${encodeURIComponent(id)}/errors`);
    moveMarker = errorChart(chart, e, total, (f) => transport.jump(f / fps));
  } catch (err) {
    chart.replaceChildren(el('p', { class: 'muted' }, `No error chart: ${err.message}`));
  }
  // The file's events (foot strikes, foot offs) on the same timeline; a click seeks there.
  if (events.length) chart.append(eventStrip(events, total, fps, (f) => transport.jump(f / fps)));

  await transport.seek(transport.t);
  return () => {
    transport.dispose();
    abort.abort();
    player.dispose();
  };

}

/**
 * Events as ticks on the take's timeline (the error chart's x axis), each named by its
 * context and label; a click on one seeks to it.
 */
function eventStrip(events, total, fps, seek) {
  const W = 1000, H = 34, L = 48, R = 8;
  const x = (f) => L + ((W - L - R) * f) / Math.max(1, total - 1);
  const s = svg('svg', { viewBox: `0 0 ${W} ${H}`, class: 'events', role: 'img',
    'aria-label': `${events.length} events: ${events.map((e) => `${e.context} ${e.label} at ${e.time_s.toFixed(2)} s`).join(', ')}` });
  const colour = (c) => (/left/i.test(c) ? '#1f5fbf' : /right/i.test(c) ? '#c0392b' : '#2e8b57');
  events.forEach((e, i) => {
    // The take's frame of the event (the file's times are on the trial's clock).
    const f = Math.min(total - 1, Math.max(0, e.frame ?? Math.round(e.time_s * fps)));
    const g = svg('g', { class: 'event', cursor: 'pointer' });
    g.append(svg('line', { x1: x(f), x2: x(f), y1: 2, y2: 20, stroke: colour(e.context), 'stroke-width': 2 }));
    const t = svg('text', { x: x(f) + 3, y: i % 2 ? 31 : 14, 'font-size': 10, fill: colour(e.context) });
    t.textContent = `${e.context ? e.context[0] : ''} ${e.label}`.trim();
    g.append(t, svg('title', {}, `${e.context} ${e.label} at ${e.time_s.toFixed(3)} s`));
    g.addEventListener('click', () => seek(f));
    s.append(g);
  });
  return s;
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
