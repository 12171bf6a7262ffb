// The live page: an open stream's figure moving as frames arrive, from the stream's
// server-sent events (`GET /v1/streams/{id}/events`), with the delay from capture to screen.
//
// Frames come in appends (a capture system sends a few frames at a time); each append is
// played out at the stream's frame rate from when it arrives, so the figure moves smoothly
// and no frame waits longer than its append did. An append that finds more than a second
// still queued replaces the queue: a live view shows now, not a backlog.
//
// A stream coded by another server (several servers on one database) has no events here:
// the page then shows the newest committed frame, polled once a second.

import { events, f32, frames as fetchFrames, json, ApiError } from './api.js';
import { el, fmt } from './dom.js';
import { showError } from './app.js';
import { shapeOf } from './frames.js';
import { Player } from './player.js';

/** Seconds of delays the page summarises. */
const DELAY_WINDOW_S = 5;

export async function livePage(main, id) {
  const take = await json(`/v1/takes/${encodeURIComponent(id)}`);
  const link = el('a', { href: `#/take/${encodeURIComponent(id)}` }, 'the stored take');
  if (!take.live) {
    main.append(el('h1', {}, take.name || take.id), el('p', {}, 'This stream has finished: see ', link, '.'));
    return () => {};
  }
  const shape = await shapeOf(take);
  const canvas = el('canvas', { class: 'view', 'aria-label': `live 3-D view of ${take.name || take.id}`, tabindex: '0' });
  const status = el('p', { class: 'status', role: 'status' }, 'connecting…');
  const cell = () => el('dd', {}, '—');
  const out = {
    received: cell(), stored: cell(), capture: cell(), arrival: cell(), skipped: cell(),
  };
  main.append(
    el('h1', {}, take.name || take.id, ' ', el('span', { class: 'badge live' }, 'live'), ' ',
      el('small', { class: 'muted' }, take.library ? `in ${take.library}` : '')),
    canvas,
    status,
    el('dl', { class: 'live-stats' },
      el('dt', {}, 'frames received'), out.received,
      el('dt', {}, 'frames stored'), out.stored,
      el('dt', { title: 'from the producer\'s capture time (captured_ms) to this screen, last 5 s' }, 'capture → visible'), out.capture,
      el('dt', { title: 'from the server taking the frames to this screen, last 5 s' }, 'server → visible'), out.arrival,
      el('dt', {}, 'appends skipped (this page fell behind)'), out.skipped),
    el('p', { class: 'muted' }, `${take.points} points at ${fmt.num(take.fps, 3)} fps, coded with ${take.codec}. `,
      'Delays are median / 95th percentile, on the server\'s clock; the producer\'s clock is taken to agree with it.'),
  );

  const player = new Player(canvas);
  const figure = player.add(shape);
  const abort = new AbortController();
  const w = take.points * 3;
  let fps = take.fps;
  let offset = 0; // this browser's clock minus the server's, ms
  let queue = []; // { frame, xyz, due (performance.now() ms), captured, received }
  let shown = -1;
  let framed = false; // the camera pointed at the figure (once a point is present)
  let skipped = 0;
  const delays = []; // [performance.now(), capture ms | null, server ms]
  let raf = 0;
  let active = true;
  let elsewhere = false; // the stream is coded by another server

  function arrive(e) {
    const data = f32(e.data);
    const now = performance.now();
    if (queue.length > fps) queue = [];
    const step = 1000 / fps;
    // Frames already queued play first; this append follows them, one frame period apart.
    const start = Math.max(now, queue.length ? queue[queue.length - 1].due + step : now);
    for (let j = 0; j < e.frames; j++) {
      queue.push({
        frame: e.first + j,
        xyz: data.subarray(j * w, (j + 1) * w),
        due: start + j * step,
        captured: e.captured_ms == null ? null : e.captured_ms - (e.frames - 1 - j) * step,
        received: e.received_ms,
      });
    }
    out.received.textContent = String(e.first + e.frames);
  }

  function draw() {
    if (!active) return;
    const now = performance.now();
    let next = null;
    while (queue.length && queue[0].due <= now) next = queue.shift();
    if (next) {
      if (!framed) framed = player.frame([[figure, next.xyz]]);
      figure.show(next.xyz);
      shown = next.frame;
      canvas.dataset.frame = String(shown);
      const server = Date.now() - offset;
      delays.push([now, next.captured == null ? null : server - next.captured, server - next.received]);
      while (delays.length && delays[0][0] < now - DELAY_WINDOW_S * 1000) delays.shift();
      summarise();
    }
    raf = requestAnimationFrame(draw);
  }

  function summarise() {
    const capture = delays.map((d) => d[1]).filter((d) => d !== null);
    const arrival = delays.map((d) => d[2]);
    out.capture.textContent = capture.length ? spread(capture) : 'the producer sends no captured_ms';
    out.arrival.textContent = spread(arrival);
    if (capture.length) out.capture.dataset.median = String(quantile(capture, 0.5));
    out.arrival.dataset.median = String(quantile(arrival, 0.5));
    out.skipped.textContent = String(skipped);
  }

  async function follow() {
    while (active) {
      let ended = false;
      try {
        await events(`/v1/streams/${encodeURIComponent(id)}/events`, (name, e) => {
          if (name === 'stream') {
            offset = Date.now() - e.server_ms;
            fps = e.fps;
            status.textContent = 'live: frames are shown as they arrive';
          } else if (name === 'frames') {
            arrive(e);
          } else if (name === 'skipped') {
            skipped += e.appends;
          } else if (name === 'end') {
            ended = true;
            status.replaceChildren(`The stream has ended (${e.reason}): see `, link, '.');
          }
        }, abort.signal);
      } catch (err) {
        if (err.name === 'AbortError') return;
        if (err instanceof ApiError && err.status === 409) return pollCommitted(err.message);
        if (err instanceof ApiError && err.status !== 0) throw err;
        status.textContent = `connection lost (${err.message}); reconnecting…`;
      }
      if (ended) return;
      await new Promise((r) => setTimeout(r, 1000));
    }
  }

  /** The newest committed frame, once a second (the stream is coded by another server). */
  async function pollCommitted(why) {
    elsewhere = true;
    status.textContent = `${why}. Showing the newest stored frame, once a second.`;
    while (active) {
      const t = await json(`/v1/takes/${encodeURIComponent(id)}`, { signal: abort.signal });
      out.stored.textContent = String(t.frames);
      if (t.frames > 0 && t.frames - 1 !== shown) {
        const r = await fetchFrames(id, t.frames - 1, t.frames, abort.signal);
        if (!framed) framed = player.frame([[figure, r.data]]);
        figure.show(r.data);
        shown = t.frames - 1;
        canvas.dataset.frame = String(shown);
      }
      if (!t.live) {
        status.replaceChildren('The stream has ended: see ', link, '.');
        return;
      }
      await new Promise((r) => setTimeout(r, 1000));
    }
  }

  /** How much of the stream is stored (committed chunk by chunk), once a second. */
  async function pollStored() {
    // Coded elsewhere, `pollCommitted` reads the same take each second and says it.
    while (active && !elsewhere) {
      const t = await json(`/v1/takes/${encodeURIComponent(id)}`, { signal: abort.signal });
      out.stored.textContent = t.frames ? `${t.frames} (${fmt.num(t.ratio, 1)}× smaller than raw)` : '0';
      if (!t.live) return;
      await new Promise((r) => setTimeout(r, 1000));
    }
  }

  raf = requestAnimationFrame(draw);
  follow().catch((e) => e.name !== 'AbortError' && showError(e));
  pollStored().catch((e) => e.name !== 'AbortError' && showError(e));
  return () => {
    active = false;
    cancelAnimationFrame(raf);
    abort.abort();
    player.dispose();
  };
}

function quantile(values, q) {
  const s = [...values].sort((a, b) => a - b);
  return s[Math.min(s.length - 1, Math.floor(q * s.length))];
}

function spread(values) {
  return `${quantile(values, 0.5).toFixed(0)} / ${quantile(values, 0.95).toFixed(0)} ms`;
}
