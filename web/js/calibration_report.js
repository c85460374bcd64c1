// Calibration report: intrinsics with their standard deviations, RMS and mean +- std of the
// corner error, a per-image error chart, each image's overlay (detected and reprojected corners),
// the mirror-rim (SVP) overlay, and the paper's manual hint: click the board's four outer corners
// on an image where detection failed, then re-run the job with them.

import { artifactUrl, get, imageUrl, post } from './api.js';
import { downloadList, listArtifacts } from './artifacts.js';
import { apiImage, clear, el, errorBox, formatNumber, formatSignificant } from './ui.js';
import { drawBarChart } from './chart.js';
import { clickableImage } from './image_overlay.js';
import { colourKey, uncertaintyColourBar } from './colorbar.js';
import { formatWithUnit, labelOf } from './labels.js';

const INTRINSICS = ['xi', 'gamma_u', 'gamma_v', 'u0', 'v0', 'alpha', 'k1', 'k2', 'k3', 'k4', 'k5'];
// Artifacts of the mirror-rim check: svp or rim as a word of the name (not the "rim" in "VMRImage").
const SVP_NAME = /(^|[_\-/.])(svp|rim)([_\-/.]|$)/i;
// The coverage report's own images (not an image's overlay).
const REPORT_IMAGES = /^(coverage|uncertainty)\.png$/i;
const UNITS = { gamma_u: 'px', gamma_v: 'px', u0: 'px', v0: 'px' };

export async function renderJobReport(container, job, setSummary) {
  const [result, artifacts] = await Promise.all([
    get(`/jobs/${encodeURIComponent(job.id)}/result`), listArtifacts(job.id).catch(() => [])]);
  renderCalibration(container, job, result, artifacts);
  const images = result.images || [];
  if (setSummary) {
    setSummary(`RMS ${formatNumber(result.rms_px, 3)} px from ${images.filter((i) => i.used).length} of ${images.length} images`);
  }
  return null;
}

export function renderCalibration(container, job, result, artifacts) {
  const camera = result.camera || {};
  const images = result.images || [];
  const used = images.filter((i) => i.used);
  const chart = el('canvas.chart#error-chart', { width: 1000, height: 220 });
  clear(container,
    el('div.card#calibration-report',
      el('h2', 'Calibration'),
      el('div.row',
        el('dl.kv.grow',
          el('dt', 'RMS reprojection error'), el('dd.big#rms', `${formatNumber(result.rms_px, 3)} px`),
          el('dt', 'Mean ± std of the Euclidean corner error'),
          el('dd#mean-std', `${formatNumber(result.mean_px, 3)} ± ${formatNumber(result.std_px, 3)} px`),
          el('dt', 'Images used'), el('dd', `${used.length} of ${images.length}`),
          el('dt', 'Image size'), el('dd', camera.image_size ? camera.image_size.join(' × ') : '–'),
          el('dt', 'Model'), el('dd', camera.model || '–')),
        el('div.grow', intrinsicsTable(camera))),
      exportsBlock(job, result.exports)),
    coverageCard(job, result.coverage),
    el('div.card', el('h2', 'Per-image RMS error'), chart,
      el('p.muted', 'Bars: RMS corner error of each image (px); grey: image not used; the line is the overall RMS.')),
    solverCard(result.solver),
    svpCard(job, artifacts, result),
    el('div.card', el('h2', 'Images'), imagesGrid(job, images, artifacts)));
  drawBarChart(chart, images.map((i) => ({
    label: i.name, value: i.used ? i.rms_px : 0, muted: !i.used, note: i.used ? '' : '×',
  })), { reference: result.rms_px, unit: 'px' });
}

function intrinsicsTable(camera) {
  const values = camera.intrinsics || {};
  const stds = camera.intrinsics_std || {};
  const names = [...INTRINSICS, ...Object.keys(values).filter((k) => !INTRINSICS.includes(k))];
  return el('table#intrinsics',
    el('thead', el('tr', el('th', 'Intrinsic'), el('th.num', 'Value'), el('th.num', '± std'), el('th', ''))),
    el('tbody', names.filter((n) => n in values).map((n) => el('tr', { dataset: { name: n } },
      el('td.mono', n), el('td.num', formatNumber(values[n], 5)),
      el('td.num', stds[n] === undefined ? '–' : `± ${formatSignificant(stds[n], 2)}`),
      el('td.muted', UNITS[n] || '')))));
}

// The calibrated camera in other tools' formats: one click each, and what the formats drop.
function exportsBlock(job, exports) {
  if (!exports) return null;
  const warnings = exports.warnings || [];
  return el('div#calibration-exports',
    el('h3', 'Use this calibration elsewhere'),
    downloadList(job.id, [
      { name: exports.opencv_omnidir, label: 'OpenCV omnidir (cv::omnidir) YAML' },
      { name: exports.kalibr, label: 'Kalibr camera YAML (omni-radtan)' }], 'export-downloads'),
    warnings.length ? el('div.warning#export-warnings', el('strong', 'What these formats leave out:'),
      el('ul', warnings.map((w) => el('li', w)))) : null);
}

// Where the board has been seen on the mirror disk, how uncertain the calibration still is
// across the image, and what to do next.
function coverageCard(job, coverage) {
  if (!coverage) return null;
  const percent = Number.isFinite(coverage.covered_fraction) ? Math.round(100 * coverage.covered_fraction) : null;
  const near = Number.isFinite(coverage.near_px) ? formatNumber(coverage.near_px, 0) : '?';
  const disk = coverage.disk_from === 'svp_rim' ? 'the mirror rim found in the image'
    : 'a circle about the principal point (the mirror rim was not measured)';
  const figure = (name, caption, id, bar) => name ? el(`figure.value-image#${id}`,
    el('a', { href: artifactUrl(job.id, name), target: '_blank', title: 'full size' },
      apiImage(artifactUrl(job.id, name), { alt: caption })), el('figcaption', caption), bar) : null;
  const advice = coverage.advice || [];
  const hasUncertainty = Number.isFinite(coverage.max_uncertainty_px);
  return el('div.card#coverage', el('h2', 'Coverage and what to do next'),
    el('dl.kv',
      el('dt', 'Board coverage'),
      el('dd.big#coverage-percent', percent === null ? '–'
        : `${percent} % of the mirror disk within ${near} px of a used corner`),
      el('dt', 'Mirror disk'), el('dd', `centre (${(coverage.disk_centre_px || []).map((x) => formatNumber(x, 1)).join(', ')}) px, ` +
        `radius ${formatNumber(coverage.disk_radius_px, 1)} px, from ${disk}`),
      el('dt', 'Projection uncertainty'),
      el('dd#max-uncertainty', hasUncertainty
        ? `at most ${formatSignificant(coverage.max_uncertainty_px, 2)} px over the disk` +
          (Number.isFinite(coverage.median_uncertainty_px) ? ` (median ${formatSignificant(coverage.median_uncertainty_px, 2)} px)` : '')
        : 'not available (the intrinsics\' covariance could not be computed)',
      hasUncertainty && coverage.uncertainty_flat === true ? '; flat over the disk'
        : hasUncertainty && coverage.uncertainty_flat === false ? '; not yet flat over the disk' : ''),
      boardPoses(coverage.board_poses)),
    el('h3', 'Advice'),
    advice.length ? el('ul.advice#coverage-advice', advice.map((a) => el('li', a)))
      : el('p.muted#coverage-advice', coverage.uncertainty_flat
        ? 'Nothing to add: every region of the mirror has corners and the uncertainty map is flat.'
        : 'The service gave no advice for this calibration.'),
    el('div.overlays',
      figure(coverage.image, 'Where the board was seen: used corners on the mirror disk', 'coverage-image',
        coverageKey(near)),
      figure(coverage.uncertainty_image, 'Uncertainty of a projected point across the image (1 σ, px)', 'uncertainty-image',
        hasUncertainty ? uncertaintyColourBar(coverage.max_uncertainty_px) : null)));
}

// How the used boards were posed: their largest tilt and their distances.
function boardPoses(poses) {
  if (!poses || !Number.isFinite(poses.median_distance_m)) return null;
  return [el('dt', 'Board poses'), el('dd#board-poses',
    `tilted up to ${formatNumber(poses.max_tilt_deg, 0)}° from facing the camera; ` +
    `${formatNumber(poses.min_distance_m, 2)} to ${formatNumber(poses.max_distance_m, 2)} m away (median ${formatNumber(poses.median_distance_m, 2)} m)`)];
}

// The coverage image's colours (engine/calib/coverage.cc: DrawCoverage).
function coverageKey(nearPx) {
  return colourKey({
    title: 'Coverage',
    items: [
      { colour: 'rgb(40, 160, 40)', label: `within ${nearPx} px of a used corner` },
      { colour: 'rgba(200, 40, 40, 0.55)', label: `farther than ${nearPx} px: no board seen there` },
      { colour: '#fff', label: 'a used corner', dot: true },
      { colour: 'rgb(0, 255, 255)', label: 'the mirror disk\'s edge' },
    ],
  });
}

function solverCard(solver) {
  if (!solver) return null;
  const scalars = Object.entries(solver).filter(([, v]) => typeof v !== 'object' || v === null);
  const nested = Object.entries(solver).filter(([, v]) => v && typeof v === 'object');
  return el('div.card', el('details#solver-summary', el('summary', 'Solver summary'),
    el('dl.kv', scalars.map(([k, v]) => [el('dt', labelOf(k)), el('dd', formatWithUnit(k, v))])),
    nested.length ? el('details', el('summary', 'Solver details (raw)'), el('pre.mono', JSON.stringify(Object.fromEntries(nested), null, 2))) : null));
}

function svpCard(job, artifacts, result) {
  const svp = artifacts.filter((a) => SVP_NAME.test(a.name) && /image\//.test(a.content_type || guessType(a.name)));
  if (!svp.length && !result.svp) return null;
  return el('div.card#svp', el('h2', 'Mirror rim (single-viewpoint check)'),
    result.svp ? el('pre.mono', JSON.stringify(result.svp, null, 2)) : null,
    el('div.overlays', svp.map((a) => el('figure',
      apiImage(artifactUrl(job.id, a.name), { loading: 'lazy', alt: a.name }), el('figcaption', a.name)))));
}

function guessType(name) {
  return /\.(png|jpe?g)$/i.test(name) ? 'image/png' : '';
}

// The overlay artifact of an image: a PNG whose name contains the image's name (folders flattened).
export function overlayFor(imageName, artifacts) {
  const stem = imageName.replace(/\.[^.]+$/, '');
  const keys = [stem, stem.replace(/\//g, '_'), stem.replace(/\//g, '-'), stem.split('/').pop()];
  const pngs = artifacts.filter((a) => /\.png$/i.test(a.name) && !SVP_NAME.test(a.name) && !REPORT_IMAGES.test(a.name));
  for (const key of keys) {
    const match = pngs.find((a) => a.name.includes(key));
    if (match) return match;
  }
  return null;
}

function imagesGrid(job, images, artifacts) {
  const datasetId = job.dataset ?? job.dataset_id;
  return el('div.overlays#image-overlays', images.map((image) => {
    const overlay = (image.overlay && artifacts.find((a) => a.name === image.overlay)) || overlayFor(image.name, artifacts);
    const src = overlay ? artifactUrl(job.id, overlay.name) : imageUrl(datasetId, image.name);
    const caption = image.used
      ? `${image.name}: RMS ${formatNumber(image.rms_px, 3)} px`
      : `${image.name}: not used — ${image.reason || 'no reason given'}`;
    const figure = el('figure', { dataset: { image: image.name, used: String(!!image.used) } },
      el('a', { href: src, target: '_blank', title: 'full size' }, apiImage(src, { loading: 'lazy', alt: image.name })),
      el('figcaption', caption));
    // The manual hint helps where detection failed, and also where it found the wrong grid.
    figure.append(el('button.hint-button', { onclick: () => openHintEditor(figure, job, image.name) },
      image.used ? 'Correct the corners by hand…' : 'Give the board corners by hand…'));
    return figure;
  }));
}

// The manual hint: four clicks on the raw image, then a new calibration job with params.hints.
function openHintEditor(figure, job, imageName) {
  const datasetId = job.dataset ?? job.dataset_id;
  const points = [];
  const messages = el('div');
  const counter = el('span');
  const rerun = el('button.primary#hint-rerun', { disabled: true, onclick: submit }, 'Re-run calibration with these corners');
  const picker = clickableImage(imageUrl(datasetId, imageName), (u, v) => {
    if (points.length >= 4) return;
    points.push([u, v]);
    update();
  });
  const update = () => {
    picker.clear();
    points.forEach(([u, v], i) => picker.marker(u, v, String(i + 1), '#f59e0b'));
    if (points.length > 1) picker.polyline([...points, ...(points.length === 4 ? [points[0]] : [])], '#f59e0b');
    counter.textContent = `${points.length} of 4 corners`;
    rerun.disabled = points.length !== 4;
  };
  const editor = el('div.card.hint-editor', { dataset: { image: imageName } },
    el('p', el('strong', imageName), ': click the four outermost inner corners of the board in this order: ',
      'the first corner, the end of the first row, the last corner, the start of the last row. ', counter),
    picker.node,
    el('p', el('button', { onclick: () => { points.length = 0; update(); } }, 'Start again'), ' ', rerun),
    messages);
  figure.replaceWith(editor);
  update();

  async function submit() {
    const params = structuredClone(job.params || {});
    params.hints = { ...(params.hints || {}), [imageName]: points.map(([u, v]) => [round2(u), round2(v)]) };
    try {
      const newJob = await post('/jobs', { type: job.type, dataset: datasetId, params });
      location.hash = `#/jobs/${encodeURIComponent(newJob.id)}`;
    } catch (err) {
      clear(messages, errorBox(err, 'The server refused the new job'));
    }
  }
}

const round2 = (x) => Math.round(x * 100) / 100;
