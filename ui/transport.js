// Playback controls shared by the take and compare pages: play/pause, speed, a scrubber, a
// loop range, the keys, and the clock that drives them. The clock counts seconds; the
// scrubber moves in ticks of `rate` per second (a take's frames, or the finest of several).

import { el } from './dom.js';

export const SPEEDS = [0.1, 0.25, 0.5, 1, 2, 4];

export class Transport {
  /**
   * @param {object} o
   * @param {number} o.last the last time that can be shown, seconds
   * @param {number} o.rate scrubber ticks per second
   * @param {URLSearchParams} o.params the page's query: t, speed, loop, from, to
   * @param {(t: number) => Promise<void>} o.onSeek show time `t` (seconds)
   * @param {() => void} o.onShare write the page's URL (with `query()`)
   * @param {(e: unknown) => void} o.onError
   */
  constructor({ last, rate, params, onSeek, onShare, onError }) {
    this.last = Math.max(0, last);
    this.rate = rate;
    this.onSeek = onSeek;
    this.onShare = onShare;
    this.onError = onError;
    this.t = this.clamp(Number(params.get('t') ?? 0) || 0);
    this.playing = false;
    this.shownTick = -1;
    this.before = 0;
    this.raf = 0;

    this.play = el('button', { class: 'play', 'aria-label': 'play' }, '▶');
    this.speed = el('select', { 'aria-label': 'speed' }, ...SPEEDS.map((s) => el('option', { value: String(s) }, `${s}×`)));
    this.speed.value = SPEEDS.includes(Number(params.get('speed'))) ? params.get('speed') : '1';
    const ticks = Math.round(this.last * rate);
    this.scrub = el('input', { type: 'range', min: '0', max: String(ticks), step: '1', value: '0', 'aria-label': 'playhead' });
    this.clock = el('output', { class: 'clock', 'aria-live': 'off' }, '0.00 s');
    this.loop = el('input', { type: 'checkbox', 'aria-label': 'loop' });
    this.loop.checked = params.get('loop') === '1';
    this.from = el('input', { type: 'number', min: '0', step: '0.1', value: params.get('from') ?? '0', 'aria-label': 'loop from (s)' });
    this.to = el('input', { type: 'number', min: '0', step: '0.1', value: params.get('to') ?? this.last.toFixed(2), 'aria-label': 'loop to (s)' });

    this.bar = el('div', { class: 'controls' }, this.play, this.speed, this.scrub, this.clock);
    this.loopBar = el('div', { class: 'controls' },
      el('label', {}, 'loop ', this.loop), el('label', {}, 'from ', this.from, ' s'), el('label', {}, 'to ', this.to, ' s'));
    this.help = el('p', { class: 'muted' }, 'Keys: space play/pause, ←/→ one frame (shift: one second), Home/End.');

    this.play.addEventListener('click', () => this.setPlaying(!this.playing));
    this.speed.addEventListener('change', () => this.onShare());
    this.loop.addEventListener('change', () => this.onShare());
    this.scrub.addEventListener('input', () => this.jump(Number(this.scrub.value) / this.rate));
    this.onKey = (e) => this.key(e);
    document.addEventListener('keydown', this.onKey);
  }

  clamp(t) {
    return Math.min(this.last, Math.max(0, t));
  }

  /** The loop range in seconds, or the whole timeline when it is empty. */
  range() {
    const a = Math.max(0, Number(this.from.value) || 0);
    const b = Math.min(this.last, Number(this.to.value) || 0);
    return b > a ? [a, b] : [0, this.last];
  }

  /** What the URL keeps of the controls. */
  query() {
    const q = new URLSearchParams({ t: String(Number(this.t.toFixed(4))), speed: this.speed.value });
    if (this.loop.checked) {
      q.set('loop', '1');
      q.set('from', this.from.value);
      q.set('to', this.to.value);
    }
    return q;
  }

  /** Show time `t`: the scrubber and clock move at once, the figure when its frame is in. */
  seek(t) {
    this.t = this.clamp(t);
    const tick = Math.floor(this.t * this.rate + 1e-6);
    this.shownTick = tick;
    this.scrub.value = String(tick);
    this.scrub.setAttribute('aria-valuetext', `${this.t.toFixed(2)} seconds`);
    this.clock.textContent = `${this.t.toFixed(2)} s`;
    return this.onSeek(this.t);
  }

  /**
   * Where the playhead rests: the middle of `t`'s tick, in whole 0.1 ms, so that the time the
   * URL keeps shows the frames shown now (a tick's edge, rounded, could fall in the one before).
   */
  rest(t) {
    const tick = Math.floor(this.clamp(t) * this.rate + 1e-6);
    return this.clamp(Number(((tick + 0.5) / this.rate).toFixed(4)));
  }

  /** A seek by the user: the URL follows. */
  jump(t) {
    this.seek(this.rest(t)).then(() => this.onShare()).catch(this.onError);
  }

  tick(now) {
    if (!this.playing) return;
    const dt = this.before ? (now - this.before) / 1000 : 0;
    this.before = now;
    let t = this.t + dt * Number(this.speed.value);
    const [a, b] = this.loop.checked ? this.range() : [0, this.last];
    if (t > b || t < a) {
      if (this.loop.checked) {
        t = a;
      } else {
        this.t = this.last;
        this.setPlaying(false);
        return;
      }
    }
    // Whole ticks are shown; the clock keeps the fraction.
    if (Math.floor(t * this.rate + 1e-6) !== this.shownTick) {
      this.seek(t).catch(this.onError);
    } else {
      this.t = t;
    }
    this.raf = requestAnimationFrame((n) => this.tick(n));
  }

  setPlaying(on, keepUrl = false) {
    this.playing = on;
    this.play.textContent = on ? '❚❚' : '▶';
    this.play.setAttribute('aria-label', on ? 'pause' : 'play');
    this.before = 0;
    if (on) {
      if (this.t >= this.last && !this.loop.checked) this.t = 0;
      this.raf = requestAnimationFrame((n) => this.tick(n));
    } else {
      cancelAnimationFrame(this.raf);
      if (!keepUrl) this.jump(this.t);
    }
  }

  key(e) {
    if (e.target instanceof HTMLInputElement && e.target.type !== 'range') return;
    if (e.target instanceof HTMLSelectElement) return;
    const step = e.shiftKey ? 1 : 1 / this.rate;
    const moves = {
      ' ': () => this.setPlaying(!this.playing),
      ArrowRight: () => this.jump(this.t + step),
      ArrowLeft: () => this.jump(this.t - step),
      Home: () => this.jump(0),
      End: () => this.jump(this.last),
    };
    const move = moves[e.key];
    if (move) {
      e.preventDefault();
      move();
    }
  }

  /** Leaving the page: stop, without writing this page's URL over the one navigated to. */
  dispose() {
    this.setPlaying(false, true);
    document.removeEventListener('keydown', this.onKey);
  }
}
