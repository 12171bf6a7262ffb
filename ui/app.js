// The viewer's shell: the hash router (#/ the library, #/take/ID?… a take, #/stats), the token
// form, and one place where errors are shown.

import { ApiError, token } from './api.js';
import { libraryPage } from './library.js';
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

async function render() {
  if (leave) {
    leave();
    leave = null;
  }
  showError(null);
  const hash = location.hash.replace(/^#/, '') || '/';
  const [path, query] = hash.split('?');
  const params = new URLSearchParams(query ?? '');
  main.replaceChildren();
  try {
    const take = path.match(/^\/take\/([^/]+)$/);
    if (take) {
      leave = await takePage(main, decodeURIComponent(take[1]), params);
    } else if (path === '/stats') {
      leave = await statsPage(main);
    } else {
      leave = await libraryPage(main, params);
    }
  } catch (e) {
    showError(e);
  }
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
  showError(e.reason);
  e.preventDefault();
});
render();
