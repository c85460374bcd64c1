// The REST API client: every call of the page to the server goes through here, so that errors
// always surface as ApiError carrying the server's JSON message ({"error": {code, message, details}}).

export const API = '/api/v1';

// The bearer token, when the server requires one (omnirig serve --token): kept in this browser's
// localStorage and sent with every API call. Images and downloads then go through fetch too,
// since <img src> and <a href> cannot carry the header.
const TOKEN_KEY = 'omnirig.token';
export const getToken = () => localStorage.getItem(TOKEN_KEY) || '';
export function setToken(token) {
  if (token) localStorage.setItem(TOKEN_KEY, token);
  else localStorage.removeItem(TOKEN_KEY);
}
function authHeaders() {
  const token = getToken();
  return token ? { Authorization: `Bearer ${token}` } : {};
}
// Tells the page (main.js) that the server wants a (different) token.
function noteUnauthorized(status) {
  if (status === 401) window.dispatchEvent(new CustomEvent('omnirig:unauthorized'));
}

export class ApiError extends Error {
  constructor(status, code, message, details) {
    super(message);
    this.status = status;
    this.code = code;
    this.details = details;
  }
}

// Turns a non-2xx response body into an ApiError with the server's own words.
function errorFromBody(status, statusText, text) {
  try {
    const body = JSON.parse(text);
    const e = body && body.error;
    if (e && e.message) return new ApiError(status, e.code || String(status), e.message, e.details);
  } catch (_) {
    // Not JSON (a proxy page, an empty body): fall through to the status line.
  }
  return new ApiError(status, String(status), `HTTP ${status} ${statusText || ''}`.trim() +
    (text ? `: ${text.slice(0, 200)}` : ''));
}

export async function request(method, path, body) {
  const init = { method, headers: authHeaders() };
  if (body !== undefined) {
    init.headers['Content-Type'] = 'application/json';
    init.body = JSON.stringify(body);
  }
  let response;
  try {
    response = await fetch(API + path, init);
  } catch (e) {
    throw new ApiError(0, 'network', `The server did not answer (${e.message}).`);
  }
  const text = await response.text();
  if (!response.ok) {
    noteUnauthorized(response.status);
    throw errorFromBody(response.status, response.statusText, text);
  }
  if (!text) return null;
  try {
    return JSON.parse(text);
  } catch (_) {
    return text;
  }
}

export const get = (path) => request('GET', path);
export const post = (path, body) => request('POST', path, body);
export const del = (path) => request('DELETE', path);

// Lists come either as a bare array or wrapped ({"datasets": [...]}, {"jobs": [...]}, {"items": [...]}).
export function asList(body, key) {
  if (Array.isArray(body)) return body;
  if (body && Array.isArray(body[key])) return body[key];
  if (body && Array.isArray(body.items)) return body.items;
  return [];
}

// Encodes an image name (which may hold one folder level, e.g. cam0/000012.png) for a URL path.
export function encodeName(name) {
  return name.split('/').map(encodeURIComponent).join('/');
}

export const imageUrl = (datasetId, name) =>
  `${API}/datasets/${encodeURIComponent(datasetId)}/images/${encodeName(name)}`;
export const artifactUrl = (jobId, name) =>
  `${API}/jobs/${encodeURIComponent(jobId)}/artifacts/${encodeName(name)}`;

// PUT of one file's raw bytes with upload progress (fetch has no upload progress, XHR does).
// onProgress(sentBytes, totalBytes). Resolves with the server's JSON, rejects with ApiError.
export function putImage(datasetId, name, file, onProgress) {
  return new Promise((resolve, reject) => {
    const xhr = new XMLHttpRequest();
    xhr.open('PUT', imageUrl(datasetId, name));
    xhr.setRequestHeader('Content-Type', file.type || 'application/octet-stream');
    for (const [k, v] of Object.entries(authHeaders())) xhr.setRequestHeader(k, v);
    xhr.upload.onprogress = (e) => onProgress && onProgress(e.loaded, e.total || file.size);
    xhr.onload = () => {
      if (xhr.status >= 200 && xhr.status < 300) {
        onProgress && onProgress(file.size, file.size);
        try {
          resolve(xhr.responseText ? JSON.parse(xhr.responseText) : null);
        } catch (_) {
          resolve(null);
        }
      } else {
        noteUnauthorized(xhr.status);
        reject(errorFromBody(xhr.status, xhr.statusText, xhr.responseText));
      }
    };
    xhr.onerror = () => reject(new ApiError(0, 'network', 'The upload was interrupted (network error).'));
    xhr.onabort = () => reject(new ApiError(0, 'aborted', 'The upload was stopped.'));
    xhr.send(file);
  });
}

// A resumable upload (PUT with Content-Range), for videos and large files: asks the server how
// much of the file it holds (GET .../uploads/{name}), then sends the rest in chunks of
// chunkBytes, each a slice of the File (never the whole file in memory). A 409 says where the
// server's part ends; a dropped connection asks again and goes on (5 times in a row at most).
// onProgress(sentBytes, totalBytes). Resolves with the stored file's JSON.
export async function putFileInChunks(datasetId, name, file, onProgress, chunkBytes = 16 << 20) {
  const statusPath = `/datasets/${encodeURIComponent(datasetId)}/uploads/${encodeName(name)}`;
  const serverOffset = async () => {
    const status = await request('GET', statusPath);
    return status && status.total_bytes === file.size ? status.received_bytes : 0;
  };
  let offset = await serverOffset();
  for (let failures = 0; ;) {
    const end = Math.min(offset + chunkBytes, file.size);
    const range = `bytes ${offset}-${end - 1}/${file.size}`;
    const base = offset;
    let answer;
    try {
      answer = await putRange(datasetId, name, file.slice(offset, end), range,
        (sent) => onProgress && onProgress(base + sent, file.size));
    } catch (err) {
      const retry = err.status === 0 || err.status >= 500 || err.code === 'upload_busy';
      if (!retry || ++failures > 5) throw err;
      await new Promise((resolve) => setTimeout(resolve, 1000));
      offset = await serverOffset();
      continue;
    }
    if (answer.status === 409) {
      if (++failures > 5) throw errorFromBody(409, 'Conflict', answer.text);
      offset = answer.json.error.details.received_bytes;
      continue;
    }
    failures = 0;
    if (answer.status !== 202) {
      onProgress && onProgress(file.size, file.size);
      return answer.json;
    }
    offset = answer.json.received_bytes;
  }
}

// One chunk's PUT; resolves {status, json, text} for 2xx and 409 (an offset mismatch), rejects
// with ApiError otherwise.
function putRange(datasetId, name, blob, range, onProgress) {
  return new Promise((resolve, reject) => {
    const xhr = new XMLHttpRequest();
    xhr.open('PUT', imageUrl(datasetId, name));
    xhr.setRequestHeader('Content-Type', 'application/octet-stream');
    xhr.setRequestHeader('Content-Range', range);
    for (const [k, v] of Object.entries(authHeaders())) xhr.setRequestHeader(k, v);
    xhr.upload.onprogress = (e) => onProgress && onProgress(e.loaded);
    xhr.onload = () => {
      let json = null;
      try {
        json = xhr.responseText ? JSON.parse(xhr.responseText) : null;
      } catch (_) {
        json = null;
      }
      const offsetMismatch = xhr.status === 409 && json && json.error &&
        json.error.code === 'upload_offset_mismatch';
      if ((xhr.status >= 200 && xhr.status < 300) || offsetMismatch) {
        resolve({ status: xhr.status, json, text: xhr.responseText });
      } else {
        noteUnauthorized(xhr.status);
        reject(errorFromBody(xhr.status, xhr.statusText, xhr.responseText));
      }
    };
    xhr.onerror = () => reject(new ApiError(0, 'network', 'The upload was interrupted (network error).'));
    xhr.onabort = () => reject(new ApiError(0, 'aborted', 'The upload was stopped.'));
    xhr.send(blob);
  });
}

// Fetches an artifact as bytes with download progress: onProgress(loaded, total).
export async function fetchArtifactBytes(jobId, name, onProgress) {
  const response = await fetch(artifactUrl(jobId, name), { headers: authHeaders() });
  if (!response.ok) {
    noteUnauthorized(response.status);
    throw errorFromBody(response.status, response.statusText, await response.text());
  }
  const total = Number(response.headers.get('Content-Length')) || 0;
  if (!response.body || !onProgress) return new Uint8Array(await response.arrayBuffer());
  const reader = response.body.getReader();
  const chunks = [];
  let loaded = 0;
  for (;;) {
    const { done, value } = await reader.read();
    if (done) break;
    chunks.push(value);
    loaded += value.length;
    onProgress(loaded, total);
  }
  const bytes = new Uint8Array(loaded);
  let offset = 0;
  for (const c of chunks) {
    bytes.set(c, offset);
    offset += c.length;
  }
  return bytes;
}

export async function fetchArtifactJson(jobId, name) {
  const bytes = await fetchArtifactBytes(jobId, name);
  return JSON.parse(new TextDecoder().decode(bytes));
}

export async function fetchArtifactText(jobId, name) {
  return new TextDecoder().decode(await fetchArtifactBytes(jobId, name));
}

// Fetches any API URL (an image, a dataset file) with the token; rejects with ApiError.
export async function fetchWithAuth(url) {
  const response = await fetch(url, { headers: authHeaders() });
  if (!response.ok) {
    noteUnauthorized(response.status);
    throw errorFromBody(response.status, response.statusText, await response.text());
  }
  return response;
}

// Shows an API image in `img`: a plain src without a token, else fetched with it.
export function setImageSource(img, url) {
  if (!getToken()) {
    img.src = url;
    return;
  }
  fetchWithAuth(url).then((r) => r.blob()).then((blob) => {
    img.src = URL.createObjectURL(blob);
  }, (err) => {
    img.alt = `${img.alt} (${err.message})`;
  });
}

// An <a> that downloads an API URL; with a token the click fetches it first.
export function downloadLink(url, filename, text) {
  const a = document.createElement('a');
  a.href = url;
  a.download = filename;
  a.textContent = text;
  a.addEventListener('click', async (e) => {
    if (!getToken() || a.dataset.ready) return;
    e.preventDefault();
    const blob = await (await fetchWithAuth(url)).blob();
    a.href = URL.createObjectURL(blob);
    a.dataset.ready = '1';
    a.click();
  });
  return a;
}
