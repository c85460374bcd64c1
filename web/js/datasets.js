// Datasets page: create and list datasets; for one dataset, upload images by drag and drop of
// files or whole folders (cam0/ and cam1/ kept), with per-file progress, resume of an interrupted
// upload (names already on the server with the same size are skipped) and thumbnails.

import { asList, del, encodeName, get, imageUrl, post, putFileInChunks, putImage } from './api.js';
import { apiImage, clear, el, errorBox, formatBytes, formatTime, progressBar, showError } from './ui.js';
import { shortId } from './labels.js';

// What a dataset holds: the images the server decodes, TUM trajectories (a SLAM job's optional
// ground truth is a file of its dataset) and videos (a SLAM job reads cam0.mp4 + cam1.mp4, or
// one stacked.mp4) and robot recordings (a ROS 1 .bag, an .mcap, a ROS 2 bag's folder: its
// metadata.yaml with its .db3 or .mcap files, or one .tar of it).
const DATASET_FILES = /(\.(png|jpe?g|bmp|pgm|ppm|pnm|tum|mp4|m4v|mov|mkv|webm|avi|bag|mcap|db3|tar)|(^|\/)metadata\.yaml)$/i;
const VIDEO = /\.(mp4|m4v|mov|mkv|webm|avi)$/i;
const RECORDING = /(\.(bag|mcap|db3|tar)|(^|\/)metadata\.yaml)$/i;
// Videos and files above this go up in chunks that resume (the server takes 64 MiB at most).
const CHUNK_BYTES = 16 << 20;
const PARALLEL_UPLOADS = 3;
const THUMBNAILS_SHOWN = 120;

export async function render(view, id) {
  return id ? renderDataset(view, id) : renderList(view);
}

// ---- the list --------------------------------------------------------------------------------

const TRAJECTORY = /\.tum$/i;

// Images, trajectories and videos apart: a dataset's "image_count" counts images and
// trajectories, "video_count" its videos.
function datasetStats(dataset) {
  const files = Array.isArray(dataset.images) ? dataset.images : null;
  const trajectories = files ? files.filter((i) => TRAJECTORY.test(i.name)) : [];
  const videos = files ? files.filter((i) => VIDEO.test(i.name)) : [];
  const recordingFiles = files ? files.filter((i) => RECORDING.test(i.name)) : [];
  const count = files ? files.length - trajectories.length - videos.length - recordingFiles.length : dataset.image_count ?? dataset.num_images ?? 0;
  const bytes = files ? files.reduce((s, i) => s + (i.size || 0), 0) : dataset.total_bytes ?? dataset.size;
  return { count, bytes, trajectories: trajectories.map((t) => t.name), videos: videos.map((v) => v.name) };
}

async function renderList(view) {
  const nameInput = el('input', { name: 'name', placeholder: 'e.g. rig-calibration-2026-11', required: true, size: 32 });
  const form = el('form.row', {
    onsubmit: async (e) => {
      e.preventDefault();
      try {
        const dataset = await post('/datasets', { name: nameInput.value.trim() });
        location.hash = `#/datasets/${encodeURIComponent(dataset.id)}`;
      } catch (err) {
        showError(form.parentElement, err, 'Could not create the dataset');
      }
    },
  }, nameInput, el('button.primary', { type: 'submit' }, 'Create dataset'));
  const table = el('div.table-scroll');
  const firstRun = el('div');
  clear(view, el('h1', 'Datasets'), firstRun, el('div.card', el('h2', 'New dataset'), form), el('div.card', table));
  const { renderFirstRun } = await import('./first_run.js');
  const stopFirstRun = await renderFirstRun(firstRun, () => refreshList(table));
  await refreshList(table);
  return stopFirstRun;
}

async function refreshList(container) {
  let datasets;
  try {
    datasets = asList(await get('/datasets'), 'datasets');
  } catch (err) {
    clear(container, errorBox(err, 'Could not list the datasets'));
    return;
  }
  if (!datasets.length) {
    clear(container, el('p.muted', 'No datasets yet: create one above, then drop images on it.'));
    return;
  }
  // The listing counts every file; each dataset's own listing tells images from trajectories.
  const details = await Promise.all(datasets.slice(0, 100).map((d) =>
    get(`/datasets/${encodeURIComponent(d.id)}`).catch(() => d)));
  const rows = details.concat(datasets.slice(100)).map((d) => {
    const { count, bytes, trajectories, videos } = datasetStats(d);
    const apart = trajectories.concat(videos);
    return el('tr', { dataset: { datasetId: d.id } },
      el('td', el('a', { href: `#/datasets/${encodeURIComponent(d.id)}` }, d.name || d.id)),
      el('td.mono', { title: d.id }, shortId(d.id)), el('td.num', { dataset: { images: count } }, String(count),
        apart.length ? el('span.muted', ` + ${apart.join(', ')}`) : null),
      el('td.num', formatBytes(bytes)),
      el('td', formatTime(d.created_at)),
      el('td', el('button.danger', {
        onclick: async () => {
          if (!confirm(`Delete dataset "${d.name || d.id}" and its images?`)) return;
          try {
            await del(`/datasets/${encodeURIComponent(d.id)}`);
            await refreshList(container);
          } catch (err) {
            showError(container, err, 'Could not delete the dataset');
          }
        },
      }, 'Delete')));
  });
  clear(container, el('table',
    el('thead', el('tr', ['Name', 'Id', 'Images', 'Size', 'Created', ''].map((h, i) =>
      el(i === 2 || i === 3 ? 'th.num' : 'th', h)))),
    el('tbody', rows)));
}

// ---- one dataset -----------------------------------------------------------------------------

async function renderDataset(view, id) {
  const summary = el('div');
  const thumbs = el('div');
  const uploads = el('div.uploads');
  const status = el('div');
  const state = { id, listed: new Map(), queue: [], running: 0, stopped: false };

  const refresh = async () => {
    try {
      const dataset = await get(`/datasets/${encodeURIComponent(id)}`);
      state.listed = new Map((dataset.images || []).map((i) => [i.name, i.size]));
      renderSummary(summary, dataset);
      renderThumbnails(thumbs, dataset, false, refresh);
    } catch (err) {
      clear(summary, errorBox(err, 'Could not load the dataset'));
    }
  };
  state.refresh = refresh;

  const fileInput = el('input', { type: 'file', multiple: true, accept: 'image/*,video/*,.tum,.bag,.mcap,.db3,.tar,.yaml', name: 'files',
    onchange: (e) => enqueueFiles(state, [...e.target.files].map((f) => ({ file: f, path: f.name })), uploads, status) });
  const folderInput = el('input', { type: 'file', multiple: true, webkitdirectory: true, name: 'folder',
    onchange: (e) => enqueueFiles(state, [...e.target.files].map((f) => ({ file: f, path: f.webkitRelativePath || f.name })), uploads, status) });
  const dropzone = el('div.dropzone#dropzone',
    el('p', el('strong', 'Drop image files, videos or whole folders here'), ' (a folder holding cam0/ and cam1/ keeps them; a recording is cam0.mp4 + cam1.mp4, or one stacked.mp4 with cam0 on top).'),
    el('p', 'or choose ', el('label', 'files ', fileInput), ' or a ', el('label', 'folder ', folderInput)),
    el('p.muted', 'An interrupted upload resumes: drop the same files again and only what the server lacks is sent (a video goes on from the last chunk the server holds).'));
  wireDropzone(dropzone, (entries) => enqueueFiles(state, entries, uploads, status));

  clear(view,
    el('p', el('a', { href: '#/datasets' }, '← all datasets')),
    summary,
    el('div.card', el('h2', 'Upload'), dropzone, status, uploads,
      el('p', el('a.button', { href: `#/jobs?dataset=${encodeURIComponent(id)}` }, 'Submit a job on this dataset →'))),
    el('div.card', el('h2', 'Images'), thumbs));
  await refresh();
  return () => { state.stopped = true; };
}

function renderSummary(container, dataset) {
  const images = (dataset.images || []).filter((i) => !TRAJECTORY.test(i.name) && !VIDEO.test(i.name) && !RECORDING.test(i.name));
  const { trajectories, videos } = datasetStats(dataset);
  const byFolder = new Map();
  for (const image of images) {
    const folder = image.name.includes('/') ? image.name.split('/')[0] : '(top level)';
    byFolder.set(folder, (byFolder.get(folder) || 0) + 1);
  }
  const sizes = new Set(images.filter((i) => i.width).map((i) => `${i.width}×${i.height}`));
  const { bytes } = datasetStats(dataset);
  clear(container, el('h1', `Dataset ${dataset.name || dataset.id}`),
    el('dl.kv.card#dataset-summary',
      el('dt', 'Id'), el('dd.mono', dataset.id),
      el('dt', 'Images'), el('dd#image-count', String(images.length)),
      el('dt', 'Trajectories'), el('dd#trajectories', trajectories.join(', ') || '–'),
      el('dt', 'Videos'), el('dd#videos', videos.join(', ') || '–'),
      el('dt', 'Recordings'), el('dd#recordings', recordingsList(dataset.recordings || [])),
      el('dt', 'Folders'), el('dd', [...byFolder].map(([f, n]) => `${f}: ${n}`).join(', ') || '–'),
      el('dt', 'Total size'), el('dd', formatBytes(bytes)),
      el('dt', 'Image sizes'), el('dd', [...sizes].join(', ') || '–'),
      el('dt', 'Created'), el('dd', formatTime(dataset.created_at))));
}

// Each recording with its topics (type, messages, rate), or what is wrong with it.
function recordingsList(recordings) {
  if (!recordings.length) return '–';
  return el('ul.recordings', recordings.map((r) => el('li',
    el('strong.mono', r.name), r.problem ? el('span.error', ` ${r.problem}`) : ` (${r.format}${r.cut_short ? ', cut short' : ''})`,
    r.note ? el('div.muted', r.note) : '',
    el('ul', (r.topics || []).map((t) => el('li.mono',
      `${t.name}  ${t.type}  ${t.message_count} msgs  ${Number(t.rate_hz).toFixed(1)} Hz`))))));
}

// `onChange` runs after a file was removed.
function renderThumbnails(container, dataset, showAll = false, onChange = null) {
  const images = dataset.images || [];
  if (!images.length) {
    clear(container, el('p.muted', 'No images yet.'));
    return;
  }
  const shown = showAll ? images : images.slice(0, THUMBNAILS_SHOWN);
  const grid = el('div.thumbs', shown.map((image) => el('figure.thumb',
    el('a', { href: imageUrl(dataset.id, image.name), target: '_blank' }, image.width
      ? apiImage(imageUrl(dataset.id, image.name), { loading: 'lazy', alt: image.name })
      : el('div.file-icon', image.name.split('.').pop())),
    el('figcaption', el('div', image.name),
      el('div.muted', `${image.width ? `${image.width}×${image.height}, ` : ''}${formatBytes(image.size)}`),
      el('button.danger.remove-image', { type: 'button', dataset: { name: image.name }, onclick: () => removeImage(container, dataset, image, onChange) },
        'Remove')))));
  const more = images.length > shown.length
    ? el('button', { onclick: () => renderThumbnails(container, dataset, true, onChange) }, `Show all ${images.length}`)
    : null;
  clear(container, grid, more);
}

// Removes one file of the dataset (refused with 409 while a job uses the dataset: the message says so).
async function removeImage(container, dataset, image, onChange) {
  if (!confirm(`Remove ${image.name} from dataset "${dataset.name || dataset.id}"?`)) return;
  try {
    await del(`/datasets/${encodeURIComponent(dataset.id)}/images/${encodeName(image.name)}`);
    if (onChange) await onChange();
  } catch (err) {
    showError(container, err, `Could not remove ${image.name}`);
  }
}

// The name an image gets on the server: its file name, kept under its camera folder when it is in
// one (cam0/000012.png); the server allows one folder level.
export function imageNameFor(path) {
  const parts = path.split('/').filter(Boolean);
  const file = parts[parts.length - 1];
  const folder = parts.length > 1 ? parts[parts.length - 2] : '';
  return /^cam\d+$/i.test(folder) ? `${folder}/${file}` : file;
}

function wireDropzone(zone, onEntries) {
  zone.addEventListener('dragover', (e) => {
    e.preventDefault();
    zone.classList.add('over');
  });
  zone.addEventListener('dragleave', () => zone.classList.remove('over'));
  zone.addEventListener('drop', async (e) => {
    e.preventDefault();
    zone.classList.remove('over');
    const items = [...(e.dataTransfer.items || [])];
    const roots = items.map((i) => i.webkitGetAsEntry && i.webkitGetAsEntry()).filter(Boolean);
    if (roots.length) {
      const entries = [];
      for (const root of roots) await walkEntry(root, '', entries);
      onEntries(entries);
    } else {
      onEntries([...e.dataTransfer.files].map((f) => ({ file: f, path: f.name })));
    }
  });
}

// Collects {file, path} of every file under a dropped file or folder entry.
async function walkEntry(entry, prefix, out) {
  const path = prefix ? `${prefix}/${entry.name}` : entry.name;
  if (entry.isFile) {
    const file = await new Promise((resolve, reject) => entry.file(resolve, reject));
    out.push({ file, path });
    return;
  }
  const reader = entry.createReader();
  for (;;) {
    const batch = await new Promise((resolve, reject) => reader.readEntries(resolve, reject));
    if (!batch.length) break;
    for (const child of batch) await walkEntry(child, path, out);
  }
}

function enqueueFiles(state, entries, list, status) {
  const skipped = [];
  let resumed = 0;
  for (const { file, path } of entries) {
    const name = imageNameFor(path);
    if (name.split('/').some((p) => p.startsWith('.')) || !DATASET_FILES.test(name)) {
      skipped.push(path);
      continue;
    }
    if (state.listed.get(name) === file.size) {
      resumed += 1;
      continue;
    }
    const row = el('div.upload-row', { dataset: { name } });
    list.append(row);
    const item = { name, file, row };
    showUploadRow(item, 0, 'queued');
    state.queue.push(item);
  }
  const notes = [];
  if (resumed) notes.push(`${resumed} already on the server (same name and size), skipped`);
  clear(status, notes.length ? el('p.notice', notes.join('; ') + '.') : null);
  if (skipped.length) {
    const shown = skipped.slice(0, 10).join(', ') + (skipped.length > 10 ? ` and ${skipped.length - 10} more` : '');
    status.append(el('p.notice#upload-skipped', `Skipped (not an image, a video or a .tum trajectory, or hidden): ${shown}.`));
  }
  pump(state, status);
}

function showUploadRow(item, fraction, label, failed = false) {
  clear(item.row, el('div.row',
    el('span.mono.grow', item.name), el('span.muted', formatBytes(item.file.size)),
    el('div', { style: 'flex: 0 0 200px' }, progressBar(fraction, label, failed))));
}

// Why the server refused a file, in words, with what to do; the row already names the file, so
// the server's "NAME: " prefix is dropped.
export function uploadErrorText(err, name) {
  let message = (err && err.message) || String(err);
  if (message.startsWith(`${name}: `)) message = message.slice(name.length + 2);
  const code = err && err.code;
  if (code === 'unsupported_media_type') return `not an image: skip it (${message})`;
  if (code === 'corrupt_image') return `a damaged image: export it again, or skip it (${message})`;
  if (code === 'corrupt_video') return `a damaged or unfinished video: copy it again from the recorder (${message})`;
  if (code === 'payload_too_large') return `too large: ${message}; skip it or make room`;
  if (code === 'insufficient_storage') return `the server's disk is full: ${message}`;
  if (code === 'network' || code === 'aborted') return `${message}: drop the same files again to resume`;
  return message;
}

// Runs up to PARALLEL_UPLOADS PUTs at once; refreshes the listing when the queue drains.
function pump(state, status) {
  while (!state.stopped && state.running < PARALLEL_UPLOADS && state.queue.length) {
    const item = state.queue.shift();
    state.running += 1;
    const upload = VIDEO.test(item.name) || RECORDING.test(item.name) || item.file.size > CHUNK_BYTES
      ? (onProgress) => putFileInChunks(state.id, item.name, item.file, onProgress, CHUNK_BYTES)
      : (onProgress) => putImage(state.id, item.name, item.file, onProgress);
    upload((sent, total) =>
      showUploadRow(item, total ? sent / total : 0, `${Math.round((100 * sent) / (total || 1))}%`))
      .then(() => {
        showUploadRow(item, 1, 'done');
        item.row.classList.add('done');
        state.listed.set(item.name, item.file.size);
      })
      .catch((err) => {
        // A refused file's bar is red and empty (not stored), never at 100 %.
        showUploadRow(item, 0, 'refused', true);
        item.row.classList.add('failed');
        item.row.append(el('div.error', { role: 'alert' }, uploadErrorText(err, item.name)));
      })
      .finally(() => {
        state.running -= 1;
        if (!state.queue.length && !state.running) {
          const failed = item.row.parentElement ? item.row.parentElement.querySelectorAll('.upload-row.failed').length : 0;
          status.append(el('p.notice#upload-finished', failed
            ? `Upload finished: ${failed} file(s) not stored (the reason is under each).`
            : 'Upload finished.'));
          state.refresh();
        }
        pump(state, status);
      });
  }
}
