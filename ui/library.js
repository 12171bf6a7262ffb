// The library page: every take with its numbers, filtered, sorted and paged through the
// listing API; files dropped on the page are uploaded with a progress bar.

import { json, upload } from './api.js';
import { showError } from './app.js';
import { el, fmt } from './dom.js';

const FILTERS = ['library', 'tag', 'layout', 'codec', 'labels'];
const SORTS = ['created', 'name', 'duration', 'frames', 'ratio', 'max_mm'];


export async function libraryPage(main, params) {
  const state = Object.fromEntries(FILTERS.map((f) => [f, params.get(f) ?? '']));
  state.sort = params.get('sort') ?? 'created';
  state.order = params.get('order') ?? (state.sort === 'created' ? 'desc' : 'asc');
  const cursors = [null];
  let page = 0;

  const form = el('form', { class: 'filters', 'aria-label': 'Filter takes' });
  for (const f of FILTERS) {
    form.append(
      el('label', {}, f, el('input', { name: f, value: state[f], placeholder: 'any', autocomplete: 'off' })),
    );
  }
  const sort = el('select', { name: 'sort' }, ...SORTS.map((s) => el('option', { value: s }, s)));
  sort.value = state.sort;
  const order = el('select', { name: 'order' }, el('option', { value: 'asc' }, 'ascending'), el('option', { value: 'desc' }, 'descending'));
  order.value = state.order;
  form.append(el('label', {}, 'sort', sort), el('label', {}, 'order', order), el('button', { type: 'submit' }, 'Apply'));
  form.addEventListener('submit', (e) => {
    e.preventDefault();
    const q = new URLSearchParams();
    for (const [k, v] of new FormData(form)) if (v) q.set(k, v);
    location.hash = `#/?${q}`;
  });

  const drop = el('div', { class: 'drop', tabindex: '0', role: 'button', 'aria-label': 'Upload files' },
    'Drop mocap files here (BVH, C3D, TRC, JSON, NPY, FBX, glTF/GLB) or ',
    el('label', { class: 'link' }, 'choose files', el('input', { type: 'file', multiple: '', hidden: '' })));
  const uploads = el('ul', { class: 'uploads' });
  const table = el('table', { class: 'takes' });
  const pager = el('div', { class: 'pager' });
  // Takes ticked in the last column, compared on the compare page.
  const chosen = new Set();
  const compare = el('button', { class: 'compare', disabled: '', onclick: () => {
    location.hash = `#/compare?ids=${[...chosen].map(encodeURIComponent).join(',')}`;
  } }, 'Compare ticked takes');
  main.append(el('h1', {}, 'Library'), form, drop, uploads, el('div', { class: 'controls' }, compare),
    el('div', { class: 'scroll' }, table), pager);

  async function load() {
    const q = new URLSearchParams({ limit: '50', sort: state.sort, order: state.order });
    for (const f of FILTERS) if (state[f] && f !== 'labels') q.set(f, state[f]);
    // `content: walk, style: happy` (as the table shows them): each a label.<key> filter.
    for (const pair of (state.labels || '').split(',')) {
      const at = pair.indexOf(':');
      if (at > 0) q.set(`label.${pair.slice(0, at).trim()}`, pair.slice(at + 1).trim());
    }
    if (cursors[page]) q.set('cursor', cursors[page]);
    const list = await json(`/v1/takes?${q}`);
    cursors[page + 1] = list.next_cursor;
    table.replaceChildren(
      el('thead', {}, el('tr', {}, ...['name', 'library', 'tags', 'labels', 'duration', 'fps', 'points', 'codec', 'ratio', 'max mm', 'mean mm', 'compare'].map((h) => el('th', { scope: 'col' }, h)))),
      el('tbody', {}, ...list.items.map(row)),
    );
    if (list.items.length === 0) table.append(el('caption', {}, 'No takes match.'));
    pager.replaceChildren(
      el('button', { onclick: () => { page -= 1; load().catch(showError); } }, '← previous'),
      el('span', {}, ` page ${page + 1} `),
      el('button', { onclick: () => { page += 1; load().catch(showError); } }, 'next →'),
    );
    if (page === 0) pager.firstChild.disabled = true;
    if (!list.next_cursor) pager.lastChild.disabled = true;
  }

  function row(t) {
    return el('tr', { 'data-id': t.id },
      el('td', {}, t.live
        ? el('a', { href: `#/live/${encodeURIComponent(t.id)}` }, t.name || t.id, ' ', el('span', { class: 'badge live' }, 'live'))
        : el('a', { href: `#/take/${encodeURIComponent(t.id)}` }, t.name || t.id)),
      el('td', {}, t.library || '—'),
      el('td', {}, (t.tags || []).join(', ')),
      el('td', {}, fmt.labels(t.labels)),
      el('td', { class: 'n' }, fmt.secs(t.duration_s)),
      el('td', { class: 'n' }, fmt.num(t.fps, 1)),
      el('td', { class: 'n' }, String(t.points)),
      el('td', {}, t.codec),
      el('td', { class: 'n' }, fmt.num(t.ratio, 1)),
      el('td', { class: 'n' }, fmt.num(t.max_mm, 3)),
      el('td', { class: 'n' }, fmt.num(t.mean_mm, 3)),
      el('td', {}, t.live ? '' : el('input', {
        type: 'checkbox', 'aria-label': `compare ${t.name || t.id}`, checked: chosen.has(t.id) ? '' : null,
        onchange: (e) => {
          if (e.target.checked) chosen.add(t.id);
          else chosen.delete(t.id);
          compare.disabled = chosen.size === 0;
          compare.textContent = `Compare ticked takes (${chosen.size})`;
        },
      })),
    );
  }

  async function send(files) {
    for (const file of files) {
      const bar = el('progress', { max: '1', value: '0' });
      const status = el('span', {}, ' uploading…');
      uploads.append(el('li', {}, `${file.name} `, bar, status));
      const q = new URLSearchParams({ name: file.name.replace(/\.[^.]+$/, '') });
      if (state.library) q.set('library', state.library);
      try {
        const r = await upload(file, q, (f) => { bar.value = f; });
        bar.value = 1;
        // A file of several animations is a take for each: the first, then `more`.
        const links = [r, ...(r.more || [])].flatMap((t, i) => [i ? ', ' : '',
          el('a', { href: `#/take/${encodeURIComponent(t.id)}` }, r.more ? t.name : 'see what compression did')]);
        status.replaceChildren(` stored as ${r.codec}, ratio ${fmt.num(r.ratio, 1)}, max ${fmt.num(r.max_mm, 3)} mm`
          + (r.more ? ` (${r.more.length + 1} animations, a take each)` : '') + ': ', ...links);
        status.className = 'ok';
      } catch (e) {
        status.textContent = ` refused: ${e.message}`;
        status.className = 'error';
      }
    }
    await load();
  }

  drop.addEventListener('dragover', (e) => { e.preventDefault(); drop.classList.add('over'); });
  drop.addEventListener('dragleave', () => drop.classList.remove('over'));
  drop.addEventListener('drop', (e) => {
    e.preventDefault();
    drop.classList.remove('over');
    send([...e.dataTransfer.files]).catch(showError);
  });
  const picker = drop.querySelector('input[type=file]');
  picker.addEventListener('change', () => send([...picker.files]).catch(showError));
  drop.addEventListener('keydown', (e) => { if (e.key === 'Enter' || e.key === ' ') { e.preventDefault(); picker.click(); } });

  await load();
  return null;
}
