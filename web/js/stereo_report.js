// Stereo report: the rig's relative pose (baseline and rotation with their uncertainties), the
// pairs used, and the epipolar explorer (the paper's Fig. 14): click a pixel in one camera's image
// and its epipolar curve, computed by the server from the calibrated rig, is drawn on the other.

import { get, imageUrl } from './api.js';
import { downloadList } from './artifacts.js';
import { clear, el, errorBox, formatNumber, formatSignificant, quaternionToAxisAngle, quaternionToRpyDeg } from './ui.js';
import { clickableImage } from './image_overlay.js';
import { drawBarChart } from './chart.js';
import { describeKey } from './labels.js';

export async function renderJobReport(container, job, setSummary) {
  const result = await get(`/jobs/${encodeURIComponent(job.id)}/result`);
  renderStereo(container, job, result);
  if (setSummary) setSummary(rigSummary(result));
  return null;
}

// What the joint fit used, counted once for the whole page (status, report and panels): the
// stereo pairs, and the given calibrations' single-camera views when there were any.
export function usedCount(result) {
  const pairs = result.pairs || [];
  const o = result.observations || {
    pairs_given: pairs.length, pairs_used: pairs.filter((p) => p.used).length, single_camera_views_given: 0,
  };
  const views = o.single_camera_views_given
    ? ` and ${o.single_camera_views_used} of ${o.single_camera_views_given} single-camera views` : '';
  return `${o.pairs_used} of ${o.pairs_given} stereo pairs${views}`;
}

// The status line of a succeeded relative_pose job.
export function rigSummary(result) {
  const std = Number.isFinite(result.baseline_std_m) ? ` ± ${formatSignificant(result.baseline_std_m * 1000, 2)}` : '';
  return `baseline ${formatNumber(result.baseline_m * 1000, 2)}${std} mm, RMS ${formatNumber(result.rms_px, 3)} px, ` +
    `from ${usedCount(result)}`;
}

export function renderStereo(container, job, result) {
  const pose = result.cam0_from_cam1 || {};
  const q = pose.rotation_wxyz || [1, 0, 0, 0];
  const t = pose.translation_m || [0, 0, 0];
  const { angleDeg, axis } = quaternionToAxisAngle(q);
  const rpy = quaternionToRpyDeg(q);
  const pairs = result.pairs || [];
  const chart = el('canvas.chart', { width: 1000, height: 200 });
  clear(container,
    el('div.card#stereo-report', el('h2', 'Stereo rig: pose of cam1 in cam0 (cam0_from_cam1)'),
      el('div.row',
        el('dl.kv.grow',
          el('dt', 'Baseline'), el('dd.big#baseline', `${formatNumber(result.baseline_m * 1000, 3)} mm`,
            result.baseline_std_m !== undefined ? ` ± ${formatNumber(result.baseline_std_m * 1000, 3)} mm` : ''),
          el('dt', 'Translation (mm)'), el('dd.mono', t.map((x) => (x * 1000).toFixed(3)).join(', '),
            withStd(result.translation_std_m && [].concat(result.translation_std_m).map((x) => x * 1000), ' mm')),
          el('dt', 'Rotation angle'), el('dd', `${formatNumber(angleDeg, 4)}° about [${axis.map((x) => formatNumber(x, 3)).join(', ')}]`,
            withStd(result.rotation_std_deg, '°')),
          el('dt', 'Roll, pitch, yaw'), el('dd', rpy.map((a) => `${formatNumber(a, 4)}°`).join(', ')),
          el('dt', 'Quaternion (w, x, y, z)'), el('dd.mono', q.map((x) => formatNumber(x, 6)).join(', ')),
          el('dt', 'RMS reprojection error'), el('dd', `${formatNumber(result.rms_px, 3)} px`),
          el('dt', 'Observations used'), el('dd#observations', usedCount(result))),
        el('div.grow', uncertaintyList(result))),
      rigExports(job, result.exports)),
    el('div.card', el('h2', 'Per-pair RMS error'), chart),
    droppedPairsCard(pairs, result.sync_test),
    el('div.card#epipolar-explorer', el('h2', 'Epipolar explorer'), epipolarExplorer(job, result)),
    camerasCard(result.cameras));
  drawBarChart(chart, pairs.map((p) => ({ label: p.name, value: p.used ? p.rms_px : 0, muted: !p.used, note: p.used ? '' : '×' })),
    { reference: result.rms_px, unit: 'px' });
}

// The rig for other tools: the Kalibr camchain (both cameras and cam1's pose), one click.
function rigExports(job, exports) {
  if (!exports) return null;
  const warnings = exports.warnings || [];
  return el('div#rig-exports', el('h3', 'Use this rig elsewhere'),
    downloadList(job.id, [{ name: exports.kalibr_camchain, label: 'Kalibr camchain YAML (both cameras and the rig)' }], 'rig-downloads'),
    warnings.length ? el('div.warning', el('strong', 'What the format leaves out:'), el('ul', warnings.map((w) => el('li', w)))) : null);
}

// The pairs the estimate left out, each with its reason in words (the chart only marks them).
function droppedPairsCard(pairs, sync) {
  const dropped = pairs.filter((p) => !p.used);
  const limit = sync && sync.run && Number.isFinite(sync.limit) ? sync.limit : null;
  return el('div.card.dropped-pairs#dropped-pairs', el('h2', `Pairs left out: ${dropped.length} of ${pairs.length}`),
    dropped.length ? el('table',
      el('thead', el('tr', ['Pair', 'Why it was left out', 'Synchronisation statistic'].map((h) => el('th', h)))),
      el('tbody', dropped.map((p) => el('tr', { dataset: { pair: p.name } },
        el('td.mono', p.name), el('td', p.reason || 'no reason given'),
        el('td.num', p.sync_statistic !== null && p.sync_statistic !== undefined
          ? `${formatNumber(p.sync_statistic, 1)}${limit !== null ? ` (limit ${formatNumber(limit, 1)})` : ''}` : '–')))))
      : el('p.muted', 'Every pair was used.'));
}

// " ± std" after a value (a number or one per axis), or nothing when the result has none.
function withStd(std, unit) {
  if (std === undefined || std === null) return null;
  const text = Array.isArray(std) ? `[${std.map((x) => formatSignificant(x, 2)).join(', ')}]` : formatSignificant(std, 2);
  return el('span.muted', ` ± ${text}${unit}`);
}

// The rig's uncertainties (1 sigma) in the headline's units: lengths in mm, angles in degrees.
const UNCERTAINTY_LABELS = {
  baseline_std_m: 'Baseline',
  baseline_std_robust_m: 'Baseline, cluster-robust over pairs',
  translation_std_m: 'Translation x, y, z',
  rotation_std_deg: 'Rotation angle',
  rotation_std_robust_deg: 'Rotation, cluster-robust over pairs',
};

// One row per uncertainty of the result (keys holding "std" or "sigma", at the top level or in
// cam0_from_cam1): its label and its value with unit; metres become millimetres.
export function uncertaintyRows(result) {
  const rows = [];
  const add = (key, value, prefix = '') => {
    if (!/std|sigma/i.test(key) || value === null || value === undefined || (typeof value === 'object' && !Array.isArray(value))) return;
    const { label, unit } = describeKey(key);
    const metres = unit === 'm';
    const shown = (x) => formatSignificant(metres ? x * 1000 : x, 2);
    const text = Array.isArray(value) ? value.map(shown).join(', ') : shown(value);
    const suffix = metres ? ' mm' : unit === '°' ? '°' : unit ? ` ${unit}` : '';
    rows.push([UNCERTAINTY_LABELS[key] || `${prefix}${label.replace(/\b(std|sigma)\b/g, '').trim()}`, `± ${text}${suffix}`]);
  };
  for (const [k, v] of Object.entries(result)) add(k, v);
  for (const [k, v] of Object.entries(result.cam0_from_cam1 || {})) add(k, v, 'cam0_from_cam1 ');
  return rows;
}

function uncertaintyList(result) {
  const rows = uncertaintyRows(result);
  if (!rows.length) return el('p.muted', 'No uncertainties in this result.');
  return el('div', el('h3', 'Uncertainties (1 σ)'), el('dl.kv#uncertainties', rows.map(([k, v]) => [el('dt', k), el('dd', v)])));
}

function camerasCard(cameras) {
  if (!cameras) return null;
  return el('div.card', el('details', el('summary', 'The two cameras\' calibrations'),
    el('pre.mono', JSON.stringify(cameras, null, 2))));
}

// The pair's base name: pairs are matched by NAME in cam0/NAME and cam1/NAME.
const pairBase = (name) => name.replace(/^cam\d+\//, '');

function epipolarExplorer(job, result) {
  const pairs = (result.pairs || []).filter((p) => p.used);
  const choices = [...(pairs.length ? pairs : result.pairs || [])].sort((a, b) => a.name.localeCompare(b.name));
  if (!choices.length) return el('p.muted', 'No image pairs in this result.');
  const datasetId = job.dataset ?? job.dataset_id;
  const select = el('select#epipolar-pair', choices.map((p) => el('option', { value: pairBase(p.name) }, pairBase(p.name))));
  const messages = el('div');
  const panes = el('div.epipolar');
  const show = () => renderPair(panes, messages, job.id, datasetId, select.value);
  select.addEventListener('change', show);
  show();
  return el('div', el('p', 'Click a pixel in either image: its epipolar curve appears in the other one. Pair ', select),
    messages, panes);
}

function renderPair(panes, messages, jobId, datasetId, base) {
  const views = {};
  const onClick = (from) => async (u, v) => {
    const to = from === 'cam0' ? 'cam1' : 'cam0';
    views.cam0.clear();
    views.cam1.clear();
    views[from].marker(u, v, `(${u.toFixed(1)}, ${v.toFixed(1)})`);
    clear(messages, el('p.muted', 'Computing the epipolar curve…'));
    try {
      const answer = await get(`/jobs/${encodeURIComponent(jobId)}/epipolar?from=${from}&u=${u.toFixed(2)}&v=${v.toFixed(2)}`);
      const polylines = answer.polylines || [];
      for (const line of polylines) if (line.length > 1) views[answer.to || to].polyline(line);
      clear(messages, el('p.muted#epipolar-status', { dataset: { from, count: String(polylines.length) } },
        polylines.length ? `Epipolar curve of ${from} pixel (${u.toFixed(1)}, ${v.toFixed(1)}) in ${answer.to || to}: ` +
          `${polylines.length} piece(s), ${polylines.reduce((s, l) => s + l.length, 0)} points.`
          : `The epipolar curve of this pixel does not cross ${to}'s image.`));
    } catch (err) {
      clear(messages, errorBox(err, 'Could not compute the epipolar curve'));
    }
  };
  for (const cam of ['cam0', 'cam1']) views[cam] = clickableImage(imageUrl(datasetId, `${cam}/${base}`), onClick(cam));
  clear(panes,
    el('figure', { dataset: { camera: 'cam0' } }, el('figcaption', `cam0/${base}`), views.cam0.node),
    el('figure', { dataset: { camera: 'cam1' } }, el('figcaption', `cam1/${base}`), views.cam1.node));
}
