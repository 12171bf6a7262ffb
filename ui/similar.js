// "Find similar" on the take page: the loop range (or the whole take) sent to
// `GET /v1/takes/{id}/similar`, the ranges found listed with their scores, each one a link to
// the compare page that plays it side by side with the query, both from their own start.

import { json } from './api.js';
import { el, fmt } from './dom.js';
import { showError } from './app.js';

/** The longest query the server takes, seconds (`MAX_SEARCH_QUERY_S`). */
const MAX_QUERY_S = 120;

/** Results asked for. */
const KS = [5, 10, 20];

/**
 * The section under a take's player. `range()` gives the seconds to search with: the loop
 * range when the loop is on, else the whole take (its first two minutes if longer).
 */
export function similarPanel(take, range) {
  const k = el('select', { class: 'similar-k', 'aria-label': 'results' }, ...KS.map((n) => el('option', { value: String(n) }, `${n} results`)));
  k.value = '10';
  const perTake = el('input', { type: 'checkbox', class: 'similar-per-take' });
  const status = el('p', { class: 'muted similar-status', 'aria-live': 'polite' });
  const results = el('div', { class: 'scroll' });
  const button = el('button', { class: 'find-similar' }, 'Find similar');
  button.addEventListener('click', async () => {
    const [a, b] = range();
    const t0 = a;
    const t1 = Math.min(b, a + MAX_QUERY_S);
    button.disabled = true;
    status.textContent = `Searching with ${t0.toFixed(2)}–${t1.toFixed(2)} s…`;
    try {
      const q = new URLSearchParams({ t0: t0.toFixed(4), t1: t1.toFixed(4), k: k.value, per_take: perTake.checked ? '3' : '1' });
      const answer = await json(`/v1/takes/${encodeURIComponent(take.id)}/similar?${q}`);
      show(answer);
    } catch (e) {
      status.textContent = '';
      results.replaceChildren();
      showError(e);
    } finally {
      button.disabled = false;
    }
  });

  function show(answer) {
    const s = answer.searched;
    const left = s.unindexed + s.live + s.without_features;
    const missing = answer.query.missing_roles?.length ? `; the query places no ${answer.query.missing_roles.join(', ')}` : '';
    status.textContent = `${answer.results.length} ranges like ${fmt.num(answer.query.t0, 2)}–${fmt.num(answer.query.t1, 2)} s, `
      + `among ${s.takes} takes (${s.windows} windows)${left ? `; ${left} not searched (${s.unindexed} not indexed yet, ${s.live} live, ${s.without_features} without features)` : ''}${missing}. Lower scores are nearer.`;
    if (!answer.results.length) {
      results.replaceChildren(el('p', { class: 'muted' }, 'Nothing found among the takes this token can see.'));
      return;
    }
    // Both play from their own start for as long as the query the server compared (its
    // windows: a second at least) lasts.
    const span = Math.max(answer.query.t1 - answer.query.t0, 1 / take.fps);
    const beside = (r) => {
      const q = new URLSearchParams({
        ids: `${take.id},${r.take}`,
        starts: `${Number(answer.query.t0.toFixed(4))},${Number(r.t0.toFixed(4))}`,
        span: String(Number(span.toFixed(4))),
        mode: 'side',
        loop: '1',
        from: '0',
        to: String(Number(span.toFixed(4))),
      });
      return `#/compare?${q}`;
    };
    const at = (r) => `#/take/${encodeURIComponent(r.take)}?t=${Number(r.t0.toFixed(4))}&loop=1&from=${Number(r.t0.toFixed(2))}&to=${Number(r.t1.toFixed(2))}`;
    results.replaceChildren(el('table', { class: 'similar' },
      el('thead', {}, el('tr', {}, ...['#', 'take', 'library', 'range s', 'frames', 'score', ''].map((h) => el('th', { scope: 'col' }, h)))),
      el('tbody', {}, ...answer.results.map((r, i) => el('tr', {},
        el('td', { class: 'n' }, String(i + 1)),
        el('td', {}, el('a', { href: at(r) }, r.name || r.take), r.missing_roles?.length ? el('small', { class: 'muted' }, ` without ${r.missing_roles.join(', ')}`) : null),
        el('td', {}, r.library || '—'),
        el('td', { class: 'n' }, `${fmt.num(r.t0, 2)}–${fmt.num(r.t1, 2)}`),
        el('td', { class: 'n' }, `${r.start}–${r.end}`),
        el('td', { class: 'n score' }, fmt.num(r.score, 3)),
        el('td', {}, el('a', { class: 'play-beside', href: beside(r), 'aria-label': `play ${r.name || r.take} ${fmt.num(r.t0, 2)}–${fmt.num(r.t1, 2)} s beside the query` }, 'play beside')),
      )))));
  }

  return el('section', { class: 'similar-panel' },
    el('h2', {}, 'Similar motion'),
    el('p', { class: 'controls' }, button, k, el('label', { title: 'more than one range from a take, if they do not overlap' }, perTake, ' several per take'),
      el('span', { class: 'muted' }, 'with the loop range (or the whole take, up to two minutes)')),
    status,
    results);
}
