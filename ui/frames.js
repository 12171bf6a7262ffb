// A stored take's frames as a page needs them: one second (a window) fetched at a time by
// range (`format=f32`), the next second fetched before the playhead needs it, and at most
// KEPT_WINDOWS seconds kept in memory. So an hour-long take opens as fast as a short one.

import { frames as fetchFrames, json } from './api.js';

/** Seconds of frames kept in memory at most, per take. */
const KEPT_WINDOWS = 120;

/** The indices of the points that play `role` in the take's body (none when unplaced). */
function playing(take, role) {
  const names = take.body?.roles?.[role] ?? [];
  return names.map((n) => take.meta.point_names.indexOf(n)).filter((i) => i >= 0);
}

/**
 * What the 3-D view needs of a take: points, bones (from its skeleton), its unit, and its
 * body: the up axis it stands along (`null` when nothing told), the floor's height along it
 * (metres), and the points of its pelvis, head (or neck) and ankles.
 */
export async function shapeOf(take) {
  const bones = [];
  if (take.skeleton) {
    const sk = await json(`/v1/skeletons/${encodeURIComponent(take.skeleton)}`);
    if (sk.hierarchy?.length === take.points) {
      sk.hierarchy.forEach((j, i) => {
        if (j.parent !== null && j.parent !== undefined) bones.push([j.parent, i]);
      });
    }
  }
  return {
    points: take.points,
    bones,
    metres: take.metres_per_unit,
    up: take.body?.up ?? null,
    floor: take.body?.floor_m ?? null,
    pelvis: playing(take, 'pelvis'),
    // The top of the body: its head, or its neck where no head marker was worn.
    head: playing(take, 'head').length ? playing(take, 'head') : playing(take, 'neck'),
    feet: [...playing(take, 'left_ankle'), ...playing(take, 'right_ankle')],
  };
}

export class TakeFrames {
  /**
   * @param {object} take the take as `GET /v1/takes/{id}` gives it
   * @param {AbortSignal} signal ends every fetch when the page is left
   * @param {() => void} [onFetch] called when a range is requested
   */
  constructor(take, signal, onFetch = () => {}) {
    this.take = take;
    this.signal = signal;
    this.onFetch = onFetch;
    this.window = Math.max(1, Math.round(take.fps));
    this.fetches = 0;
    this.pending = new Map(); // window index -> Promise<Float32Array>
    this.ready = new Map(); // window index -> Float32Array, once loaded
  }

  /** The frame shown at `seconds` into the take (clamped to the take). */
  frameAt(seconds) {
    const f = Math.floor(seconds * this.take.fps + 1e-6);
    return Math.min(this.take.frames - 1, Math.max(0, f));
  }

  load(index) {
    let w = this.pending.get(index);
    if (!w) {
      const start = index * this.window;
      const end = Math.min(this.take.frames, start + this.window);
      this.fetches += 1;
      this.onFetch();
      w = fetchFrames(this.take.id, start, end, this.signal).then((r) => r.data);
      w.catch(() => this.pending.delete(index));
      this.pending.set(index, w);
      if (this.pending.size > KEPT_WINDOWS) this.pending.delete(this.pending.keys().next().value);
    }
    return w;
  }

  /** Frame `f`'s positions (points × 3, stored units, NaN where missing). */
  async at(f) {
    const index = Math.floor(f / this.window);
    let data = this.ready.get(index);
    if (!data) {
      data = await this.load(index);
      this.ready.set(index, data);
      if (this.ready.size > KEPT_WINDOWS) this.ready.delete(this.ready.keys().next().value);
    }
    const n = this.take.points * 3;
    const k = f - index * this.window;
    return data.subarray(k * n, (k + 1) * n);
  }

  /** Fetch the second after frame `f`'s before the playhead gets there. */
  prefetch(f) {
    const next = Math.floor(f / this.window) + 1;
    if (next * this.window < this.take.frames) this.load(next).catch(() => {});
  }
}
