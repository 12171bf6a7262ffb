// The /v1 API as the viewer calls it: the user's token (kept in this browser only), and
// every error answer turned into an ApiError carrying the server's code and message.

const KEY = 'mocapstore.token';

export const token = {
  get: () => localStorage.getItem(KEY) || '',
  set: (t) => (t ? localStorage.setItem(KEY, t) : localStorage.removeItem(KEY)),
};

export class ApiError extends Error {
  constructor(status, code, message) {
    super(message);
    this.status = status;
    this.code = code;
  }
}

function headers(type) {
  const h = {};
  if (type) h['Content-Type'] = type;
  const t = token.get();
  if (t) h.Authorization = `Bearer ${t}`;
  return h;
}

async function errorOf(r) {
  let code = `http_${r.status}`;
  let message = r.statusText || `HTTP ${r.status}`;
  try {
    const j = await r.json();
    code = j.error.code;
    message = j.error.message;
  } catch {
    // Not the JSON error shape (a proxy's page, say): keep the status line.
  }
  return new ApiError(r.status, code, message);
}

export async function request(path, { method = 'GET', body, type, signal } = {}) {
  let r;
  try {
    r = await fetch(path, { method, body, headers: headers(type), signal });
  } catch (e) {
    if (e.name === 'AbortError') throw e;
    throw new ApiError(0, 'network', `the server cannot be reached (${e.message})`);
  }
  if (!r.ok) throw await errorOf(r);
  return r;
}

export async function json(path, opts) {
  return (await request(path, opts)).json();
}

/** Frames [start, end) of a take as positions: { start, count, points, data: Float32Array }. */
export async function frames(id, start, end, signal) {
  const r = await request(
    `/v1/takes/${encodeURIComponent(id)}/frames?start=${start}&end=${end}&format=f32`,
    { signal },
  );
  const data = new Float32Array(await r.arrayBuffer());
  return {
    start: Number(r.headers.get('x-start-frame')),
    count: Number(r.headers.get('x-frames')),
    points: Number(r.headers.get('x-points')),
    data,
  };
}

/**
 * Server-sent events from `path`, read through fetch (EventSource cannot send the token):
 * `onEvent(name, data)` for each event, data parsed as JSON. Resolves when the server ends
 * the stream; rejects with an ApiError if it refuses it.
 */
export async function events(path, onEvent, signal) {
  const r = await request(path, { signal });
  const reader = r.body.pipeThrough(new TextDecoderStream()).getReader();
  let buffer = '';
  for (;;) {
    const { value, done } = await reader.read();
    if (done) return;
    buffer += value.replace(/\r\n?/g, '\n');
    let cut;
    while ((cut = buffer.indexOf('\n\n')) >= 0) {
      const block = buffer.slice(0, cut);
      buffer = buffer.slice(cut + 2);
      let name = 'message';
      const data = [];
      for (const line of block.split('\n')) {
        if (line.startsWith('event:')) name = line.slice(6).trim();
        else if (line.startsWith('data:')) data.push(line.slice(5).replace(/^ /, ''));
      }
      // Comment lines alone (the server's keep-alive) make no event.
      if (data.length) onEvent(name, JSON.parse(data.join('\n')));
    }
  }
}

/** Little-endian f32 values from base64. */
export function f32(base64) {
  const bytes = Uint8Array.from(atob(base64), (c) => c.charCodeAt(0));
  return new Float32Array(bytes.buffer);
}

/** A file download through the API (the token goes in a header, so not a plain link). */
export async function download(path, filename) {
  const r = await request(path);
  const url = URL.createObjectURL(await r.blob());
  const a = document.createElement('a');
  a.href = url;
  a.download = filename;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10_000);
}

/** Upload a file as a new take; `progress(fraction)` as it is sent. Resolves to the report. */
export function upload(file, query, progress) {
  return new Promise((resolve, reject) => {
    const x = new XMLHttpRequest();
    x.open('POST', `/v1/takes?${query}`);
    x.setRequestHeader('Content-Type', 'application/octet-stream');
    const t = token.get();
    if (t) x.setRequestHeader('Authorization', `Bearer ${t}`);
    x.upload.onprogress = (e) => e.lengthComputable && progress(e.loaded / e.total);
    x.onerror = () => reject(new ApiError(0, 'network', 'the upload could not reach the server'));
    x.onload = () => {
      let body = null;
      try {
        body = JSON.parse(x.responseText);
      } catch {
        // handled below
      }
      if (x.status >= 200 && x.status < 300) resolve(body);
      else
        reject(
          new ApiError(
            x.status,
            body?.error?.code ?? `http_${x.status}`,
            body?.error?.message ?? `HTTP ${x.status}`,
          ),
        );
    };
    x.send(file);
  });
}
