// The viewer's shell: the hash router (#/ the library, #/take/ID?… a take, #/live/ID an open
// stream, #/compare?ids=… takes in step, #/stats), the token form, and one place where
// errors are shown.

import { ApiError, token } from './api.js';
import { comparePage } from './compare.js';
import { libraryPage } from './library.js';
import { livePage } from './live.js';
import { statsPage } from './stats.js';
import { takePage } from './take.js';

const main = document.getElementById('main');
const box = document.getElementById('message');

/** Show an error (or clear with null); a 401 says what to do about it. */
export function showError(e) {
  if (!e) {
    box.hidden = true;
    box.textContent = '';
    return;
  }
  let text = e instanceof ApiError ? `${e.message} (${e.code})` : String(e.message ?? e);
  if (e instanceof ApiError && e.status === 401) {
    text += ' — enter an API token above (mocapstore token create --scope read …).';
  }
  box.textContent = text;
  box.hidden = false;
}

let leave = null;
let generation = 0;

/**
 * Show the page the hash names. Each render gets its own box: a page still loading when the
 * hash changes again ends up detached, and is disposed as soon as it has loaded.
 */
async function render() {
  const mine = ++generation;
  if (leave) {
    leave();
    leave = null;
  }
  showError(null);
  const hash = location.hash.replace(/^#/, '') || '/';
  const [path, query] = hash.split('?');
  const params = new URLSearchParams(query ?? '');
  const box = document.createElement('div');
  main.replaceChildren(box);
  let done = null;
  try {
    const take = path.match(/^\/take\/([^/]+)$/);
    const live = path.match(/^\/live\/([^/]+)$/);
    if (take) {
      done = await takePage(box, decodeURIComponent(take[1]), params);
    } else if (live) {
      done = await livePage(box, decodeURIComponent(live[1]));
    } else if (path === '/compare') {
      done = await comparePage(box, params);
    } else if (path === '/stats') {
      done = await statsPage(box);
    } else {
      done = await libraryPage(box, params);
    }
  } catch (e) {
    if (mine === generation) showError(e);
  }
  if (mine === generation) leave = done;
  else if (done) done();
}

const form = document.getElementById('token-form');
const input = document.getElementById('token');
input.value = token.get();
form.addEventListener('submit', (e) => {
  e.preventDefault();
  token.set(input.value.trim());
  render();
});

window.addEventListener('hashchange', render);
window.addEventListener('unhandledrejection', (e) => {
  if (e.reason?.name !== 'AbortError') showError(e.reason);
  e.preventDefault();
});
render();
