// A job's artifacts: every file downloadable, with its size and type.

import { API, artifactUrl, asList, downloadLink, get } from './api.js';
import { clear, el, errorBox, formatBytes } from './ui.js';

export async function listArtifacts(jobId) {
  return asList(await get(`/jobs/${encodeURIComponent(jobId)}/artifacts`), 'artifacts');
}

// Every artifact of the job in one zip (GET .../artifacts.zip, streamed by the server).
export function zipLink(jobId, artifacts, jobType) {
  const total = artifacts.reduce((s, a) => s + (a.size || 0), 0);
  const link = downloadLink(`${API}/jobs/${encodeURIComponent(jobId)}/artifacts.zip`,
    `${jobType ? `${jobType}-` : ''}${jobId}.zip`,
    `Download all as zip (${artifacts.length} file${artifacts.length === 1 ? '' : 's'}, ${formatBytes(total)})`);
  link.className = 'button primary download-zip';
  link.id = 'download-zip';
  return link;
}

export async function renderArtifacts(container, jobId, jobType) {
  let artifacts;
  try {
    artifacts = await listArtifacts(jobId);
  } catch (err) {
    clear(container, el('h2', 'Artifacts'), errorBox(err, 'Could not list the artifacts'));
    return;
  }
  const total = artifacts.reduce((s, a) => s + (a.size || 0), 0);
  clear(container, el('h2', `Artifacts (${artifacts.length}, ${formatBytes(total)})`),
    artifacts.length ? el('p', zipLink(jobId, artifacts, jobType)) : null,
    artifacts.length ? el('div.table-scroll', el('table',
      el('thead', el('tr', el('th', 'File'), el('th.num', 'Size'), el('th', 'Type'), el('th', 'sha256'))),
      el('tbody', artifacts.map((a) => el('tr', { dataset: { artifact: a.name } },
        el('td', downloadLink(artifactUrl(jobId, a.name), a.name.split('/').pop(), a.name)),
        el('td.num', formatBytes(a.size)), el('td', a.content_type || ''),
        el('td.mono.muted', { title: a.sha256 || '' }, (a.sha256 || '').slice(0, 12))))))) :
      el('p.muted', 'This job wrote no artifacts.'));
}

// One-click downloads of named artifacts: [{name, label}] (entries without a name are left out).
// Each link carries data-artifact with the artifact's name.
export function downloadList(jobId, files, id) {
  const shown = files.filter((f) => f && f.name);
  if (!shown.length) return null;
  return el(`ul.downloads${id ? `#${id}` : ''}`, shown.map((f) => {
    const link = downloadLink(artifactUrl(jobId, f.name), f.name.split('/').pop(), `Download ${f.label}`);
    link.className = 'download';
    link.dataset.artifact = f.name;
    return el('li', link, el('span.muted.mono', ` ${f.name}`));
  }));
}
