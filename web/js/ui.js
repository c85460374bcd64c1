// Small DOM and formatting helpers shared by the pages.

import { setImageSource } from './api.js';

// el('div.card#main', {onclick: f, title: 't'}, child, 'text', ...): a DOM element.
export function el(spec, attrs, ...children) {
  const [tagAndClasses, id] = spec.split('#');
  const [tag, ...classes] = tagAndClasses.split('.');
  const node = document.createElement(tag || 'div');
  if (classes.length) node.className = classes.join(' ');
  if (id) node.id = id;
  if (attrs && (typeof attrs !== 'object' || attrs instanceof Node || Array.isArray(attrs))) {
    children.unshift(attrs);
    attrs = null;
  }
  for (const [key, value] of Object.entries(attrs || {})) {
    if (value === undefined || value === null || value === false) continue;
    if (key.startsWith('on')) node.addEventListener(key.slice(2), value);
    else if (key === 'dataset') Object.assign(node.dataset, value);
    else if (key in node && typeof value !== 'string') node[key] = value;
    else node.setAttribute(key, value === true ? '' : value);
  }
  append(node, children);
  return node;
}

function append(node, children) {
  for (const child of children.flat(Infinity)) {
    if (child === undefined || child === null || child === false) continue;
    node.append(child instanceof Node ? child : document.createTextNode(String(child)));
  }
}

// An <img> of an API URL (sent with the bearer token when there is one).
export function apiImage(url, attrs = {}) {
  const img = el('img', attrs);
  setImageSource(img, url);
  return img;
}

export function clear(node, ...children) {
  node.replaceChildren();
  append(node, children);
  return node;
}

export function formatBytes(n) {
  if (n === undefined || n === null || Number.isNaN(n)) return '?';
  const units = ['B', 'kB', 'MB', 'GB', 'TB'];
  let value = Number(n);
  let unit = 0;
  while (value >= 1000 && unit < units.length - 1) {
    value /= 1000;
    unit += 1;
  }
  return `${value.toFixed(unit === 0 ? 0 : value < 10 ? 2 : 1)} ${units[unit]}`;
}

export function formatDuration(seconds) {
  if (seconds === undefined || seconds === null || !Number.isFinite(seconds)) return '';
  const s = Math.max(0, Math.round(seconds));
  if (s < 60) return `${s} s`;
  if (s < 3600) return `${Math.floor(s / 60)} min ${s % 60} s`;
  return `${Math.floor(s / 3600)} h ${Math.floor((s % 3600) / 60)} min`;
}

export function formatNumber(x, digits = 4) {
  if (x === undefined || x === null) return '–';
  if (typeof x !== 'number') return String(x);
  if (x !== 0 && (Math.abs(x) >= 1e5 || Math.abs(x) < 1e-3)) return x.toExponential(digits - 1);
  return x.toFixed(digits);
}

// Uncertainties: a few significant digits whatever the magnitude.
export function formatSignificant(x, digits = 2) {
  if (x === undefined || x === null) return '–';
  if (typeof x !== 'number' || x === 0) return String(x);
  return Math.abs(x) >= 1e5 || Math.abs(x) < 1e-4 ? x.toExponential(digits - 1) : String(Number(x.toPrecision(digits)));
}

export function formatTime(iso) {
  if (!iso) return '';
  const date = typeof iso === 'number' ? new Date(iso * 1000) : new Date(iso);
  return Number.isNaN(date.getTime()) ? String(iso) : date.toLocaleString();
}

// A message as a person reads it: without the source locations the engine's checks append
// ("(calib/pipeline.cc:42)"), which help whoever reads the job's log, not the page.
export function readable(message) {
  return String(message ?? '').replace(/ \([\w./-]+\.(cc|h):\d+\)/g, '');
}

// A box showing an API error's message (and its code and details, for whoever reports a bug).
export function errorBox(error, context) {
  const message = readable((error && error.message) || String(error));
  const code = error && error.code ? ` (${error.code})` : '';
  const details = error && error.details && Object.keys(error.details).length ? JSON.stringify(error.details) : '';
  return el('div.error', { role: 'alert' },
    el('strong', context ? `${context}: ` : 'Error: '), message, el('span.muted', code),
    details ? el('div.details', details) : null);
}

// Shows an error at the top of a container without clearing it.
export function showError(container, error, context) {
  const box = errorBox(error, context);
  container.prepend(box);
  return box;
}

// A progress bar; `failed` turns it red, stopped where the work stopped.
export function progressBar(fraction, label, failed = false) {
  const pct = Math.max(0, Math.min(1, Number(fraction) || 0)) * 100;
  return el(failed ? 'div.progress.failed' : 'div.progress', { role: 'progressbar', 'aria-valuenow': pct.toFixed(0),
    'aria-valuemin': '0', 'aria-valuemax': '100' },
  el('div.bar', { style: `width:${pct.toFixed(1)}%` }), el('span', label ?? `${pct.toFixed(0)}%`));
}

// Quaternion (w, x, y, z) to a rotation angle in degrees and a unit axis.
export function quaternionToAxisAngle([w, x, y, z]) {
  const n = Math.hypot(w, x, y, z) || 1;
  [w, x, y, z] = [w / n, x / n, y / n, z / n];
  if (w < 0) [w, x, y, z] = [-w, -x, -y, -z];
  const s = Math.hypot(x, y, z);
  const angle = 2 * Math.atan2(s, w);
  const axis = s > 1e-12 ? [x / s, y / s, z / s] : [0, 0, 1];
  return { angleDeg: (angle * 180) / Math.PI, axis };
}

// Quaternion (w, x, y, z) to roll (x), pitch (y), yaw (z) in degrees, for R = Rz(yaw) Ry(pitch) Rx(roll).
export function quaternionToRpyDeg([w, x, y, z]) {
  const roll = Math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y));
  const pitch = Math.asin(Math.max(-1, Math.min(1, 2 * (w * y - z * x))));
  const yaw = Math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z));
  return [roll, pitch, yaw].map((a) => (a * 180) / Math.PI);
}

// Plain-words explanation of a failed job from its error code and message.
export function explainJobError(error) {
  if (!error) return 'The job failed without saying why.';
  const code = String(error.code || '').toLowerCase();
  // The codes the server writes (server/job_runner.cc, storage/): say what each means.
  const hints = {
    invalid_input: 'The images or the parameters could not be used',
    job_failed: 'The computation failed',
    interrupted: 'The server stopped while the job ran, too many times; retry it',
    unknown_type: 'This server does not run this kind of job',
  };
  const lead = hints[code] || 'The job failed';
  return `${lead}: ${readable(error.message) || 'no message'}`;
}

// A failed job's message as readable lines: the engine joins several reasons (one per image or
// pair) with "; " or newlines, and lists after a colon ("... images without a partner: a, b").
export function errorLines(message) {
  return readable(message).split(/\n|;(?:\s+|$)/).map((line) => line.trim()).filter(Boolean);
}

// One short line of a failed job, for lists: the first reason, cut at 140 characters.
export function shortJobError(error) {
  const lines = errorLines(error && error.message);
  const first = lines[0] || explainJobError(error);
  const cut = first.length > 140 ? `${first.slice(0, 137)}…` : first;
  return lines.length > 1 ? `${cut} (+${lines.length - 1} more)` : cut;
}

// Keeps a polling loop alive only while its element is in the document.
export function poll(node, intervalMs, tick) {
  let timer = null;
  let seen = false;  // the node may be attached just after poll() is called
  const loop = async () => {
    if (node.isConnected) seen = true;
    else if (seen) return;
    try {
      await tick();
    } finally {
      if (node.isConnected || !seen) timer = setTimeout(loop, intervalMs);
    }
  };
  timer = setTimeout(loop, 0);
  return () => clearTimeout(timer);
}
