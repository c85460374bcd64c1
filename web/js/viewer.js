// The 3D viewer (SLAM and stereo reconstruction): the coloured point cloud, the trajectory and
// the rig poses with orbit, pan, zoom and a point size control; a top view of the trajectory
// against the ground truth when there is one; the per-frame statistics.
// #/viewer/JOB_ID shows a job's artifacts; #/viewer alone opens a local PLY file.
//
// Stays responsive with millions of points: one BufferGeometry with typed arrays straight from the
// PLY parser, one Points draw call, and rendering only when the view changes.

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { asList, fetchArtifactBytes, fetchArtifactJson, fetchArtifactText, fetchWithAuth, get, imageUrl } from './api.js';
import { listArtifacts, renderArtifacts } from './artifacts.js';
import { parsePly } from './ply.js';
import { reconstructPairsCard } from './reconstruct_report.js';
import {
  drawTopView, GROUND_TRUTH_COLOUR, inversePose, LOOP_COLOUR, loopSegments, OCCUPANCY_COLOURS, parseOccupancy, parseTum,
  STATE_COLOURS, trajectoryFromJson, transformTrajectory,
} from './topview.js';
import { colourBar, colourKey, TURBO } from './colorbar.js';
import { colourModes, percentileRange, pointValues, turboColours } from './cloud_colour.js';
import { describeKey, formatLength, formatWithUnit, shortId } from './labels.js';
import { slamErrorsCard } from './slam_report.js';
import { clear, el, errorBox, formatBytes, formatNumber, formatTime, progressBar } from './ui.js';

// Clouds larger than this wait for a click (their size shown) instead of loading with the page.
const AUTO_LOAD_BYTES = 20e6;
const CLOUD_JOB_TYPES = ['slam', 'stereo_reconstruct'];

export async function render(view, id, query) {
  if (id) {
    const job = await get(`/jobs/${encodeURIComponent(id)}`);
    const datasetId = job.dataset ?? job.dataset_id;
    const dataset = await get(`/datasets/${encodeURIComponent(datasetId)}`).catch(() => ({}));
    const report = el('div');
    const artifacts = el('div.card#artifacts');
    clear(view, el('p', el('a', { href: `#/jobs/${encodeURIComponent(id)}` }, `← the ${job.type} job ${shortId(id)}`)),
      el('h1', { title: `job ${id}` }, `3D viewer: ${job.type} of “${dataset.name || shortId(datasetId)}” · ${shortId(id)}`),
      report, artifacts);
    const cleanup = await renderJobReport(report, job, null, query && query.get('cloud'));
    await renderArtifacts(artifacts, id, job.type);
    return cleanup;
  }
  return renderLocal(view);
}

// ---- a local PLY file ------------------------------------------------------------------------

function renderLocal(view) {
  const holder = el('div');
  let scene = null;
  const open = async (file) => {
    if (scene) scene.dispose();
    clear(holder, el('p.muted', `Reading ${file.name} (${formatBytes(file.size)})…`));
    try {
      const cloud = parsePly(await file.arrayBuffer());
      clear(holder);
      scene = createScene(holder, { cloud, title: file.name });
    } catch (err) {
      clear(holder, errorBox(err, `Could not read ${file.name}`));
    }
  };
  const input = el('input#ply-file', { type: 'file', accept: '.ply', onchange: (e) => e.target.files[0] && open(e.target.files[0]) });
  const jobs = el('div.table-scroll#cloud-jobs', el('p.muted', 'Looking for jobs with point clouds…'));
  clear(view, el('h1', '3D viewer'),
    el('div.card', el('h2', 'Point clouds of the jobs'), jobs),
    el('div.card', el('p', 'Or open a PLY point cloud from this computer: ', input)), holder);
  listCloudJobs(jobs);
  return () => scene && scene.dispose();
}

// The succeeded slam and stereo_reconstruct jobs with their PLY clouds and sizes, newest first;
// each cloud opens in the viewer page of its job.
async function listCloudJobs(container) {
  try {
    const [datasets, ...lists] = await Promise.all([get('/datasets'),
      ...CLOUD_JOB_TYPES.map((type) => get(`/jobs?state=succeeded&type=${type}&limit=30`))]);
    const names = new Map(asList(datasets, 'datasets').map((d) => [d.id, d.name]));
    const jobs = lists.flatMap((l) => asList(l, 'jobs'))
      .sort((a, b) => String(b.finished_at || b.created_at).localeCompare(String(a.finished_at || a.created_at))).slice(0, 30);
    const withClouds = await Promise.all(jobs.map(async (job) => {
      const plys = (await listArtifacts(job.id).catch(() => [])).filter((a) => /\.ply$/i.test(a.name));
      const previews = new Map(plys.filter((a) => isPreview(a.name)).map((a) => [fullCloudName(a.name), a]));
      return { job, clouds: plys.filter((a) => !isPreview(a.name)).map((a) => ({ ...a, preview: previews.get(a.name) })) };
    }));
    const rows = withClouds.filter((j) => j.clouds.length);
    if (!rows.length) {
      clear(container, el('p.muted', 'No slam or stereo_reconstruct job has a point cloud yet.'));
      return;
    }
    clear(container, el('table',
      el('thead', el('tr', ['Job', 'Dataset', 'Finished', 'Clouds (size before download)'].map((h) => el('th', h)))),
      el('tbody', rows.map(({ job, clouds }) => {
        const datasetId = job.dataset ?? job.dataset_id;
        const href = (name) => `#/viewer/${encodeURIComponent(job.id)}?cloud=${encodeURIComponent(name)}`;
        return el('tr', { dataset: { jobId: job.id } },
          el('td', el('a', { href: `#/viewer/${encodeURIComponent(job.id)}`, title: job.id }, `${job.type} · ${shortId(job.id)}`)),
          el('td', { title: datasetId }, names.get(datasetId) || shortId(datasetId)),
          el('td', formatTime(job.finished_at)),
          el('td', el('ul.cloud-list', clouds.map((a) => el('li',
            el('a.cloud-link', { href: href(a.name), dataset: { artifact: a.name, size: String(a.size) } }, a.name),
            el('span.muted', ` ${formatBytes(a.size)}`),
            a.preview ? el('span.muted.preview-size', ` (opens as a ${formatBytes(a.preview.size)} preview)`) : null)))));
      }))));
  } catch (err) {
    clear(container, errorBox(err, 'Could not list the jobs'));
  }
}

// ---- a job's results -------------------------------------------------------------------------

// NAME.preview.ply: the job's preview of NAME.ply (a random subset of at most ~2 M points and
// ~20 MB, every property kept).
const isPreview = (name) => /\.preview\.ply$/i.test(name);
const fullCloudName = (name) => name.replace(/\.preview\.ply$/i, '.ply');

function pick(artifacts, pattern) {
  return artifacts.find((a) => pattern.test(a.name));
}

// The cloud to show: the one the result names (slam: artifacts.map_ply, stereo_reconstruct:
// artifact), else map.ply or cloud.ply, else any PLY that is not a pose file.
function mainCloud(artifacts, result) {
  const named = (result.artifacts && result.artifacts.map_ply) || result.artifact;
  return (named && artifacts.find((a) => a.name === named)) || pick(artifacts, /(^|\/)(map|cloud)\.ply$/i) ||
    artifacts.find((a) => /\.ply$/i.test(a.name) && !/pose|rig|camera/i.test(a.name)) || pick(artifacts, /\.ply$/i);
}

// Shown under a succeeded slam or stereo_reconstruct job (`preferred`: the cloud to show
// first). Returns a cleanup function.
export async function renderJobReport(container, job, setSummary, preferred) {
  const artifacts = await listArtifacts(job.id);
  const result = await get(`/jobs/${encodeURIComponent(job.id)}/result`).catch(() => ({}));
  // The clouds to choose from are the full ones; each large one's preview (NAME.preview.ply,
  // built by the job) is what loads first.
  const clouds = artifacts.filter((a) => /\.ply$/i.test(a.name) && !isPreview(a.name));
  const previews = new Map(artifacts.filter((a) => isPreview(a.name)).map((a) => [fullCloudName(a.name), a]));
  const status = el('div');
  const sceneHolder = el('div');
  const below = el('div');
  const cloudSelect = clouds.length > 1 ? el('select#cloud-select', clouds.map((a) =>
    el('option', { value: a.name }, `${a.name} (${formatBytes(a.size)})`))) : null;
  const headline = job.type === 'slam' ? slamHeadline(result) : null;
  if (headline && setSummary) setSummary(headline.text);
  clear(container, headline ? headline.card : null, job.type === 'slam' ? slamErrorsCard(result.evaluation) : null,
    el('div.card', el('h2', 'Point cloud and trajectory'),
      cloudSelect ? el('p', 'Cloud: ', cloudSelect) : null, status, sceneHolder), below);

  const [trajectory, groundTruth, report, occupancy] = await Promise.all([
    loadTrajectory(job, artifacts, result), loadGroundTruth(job, artifacts, result),
    Promise.resolve(loadReport(job.id, artifacts, result)), loadOccupancy(job.id, artifacts)]);
  let scene = null;
  let shown = 0;  // the latest request: an earlier load that finishes later is dropped
  const show = async (artifact, confirmed = false) => {
    const request = ++shown;
    if (scene) scene.dispose();
    scene = null;
    clear(sceneHolder);
    const preview = artifact && !confirmed ? previews.get(artifact.name) : null;
    const fullButton = () => el('button.primary#load-cloud', { type: 'button', dataset: { artifact: artifact.name },
      onclick: () => show(artifact, true) }, `Load the full cloud ${artifact.name} (${formatBytes(artifact.size)})`);
    if (artifact && !preview && !confirmed && artifact.size > AUTO_LOAD_BYTES) {
      // A large cloud without a preview is fetched on request only, its size stated first.
      clear(status, el('p#cloud-size-note', `${artifact.name} is ${formatBytes(artifact.size)}. `, fullButton()));
      if (trajectory) scene = createScene(sceneHolder, { cloud: null, trajectory, title: 'trajectory' });
      return;
    }
    const loading = preview || artifact;
    const cloud = loading ? await loadCloud(job.id, loading, status) : null;
    if (request !== shown) return;
    if (preview && cloud) {
      clear(status, el('p#cloud-size-note', { dataset: { preview: preview.name } },
        `A preview: ${cloud.count.toLocaleString('en-US')} points (${formatBytes(preview.size)}) picked at random from ` +
        `${artifact.name} (${formatBytes(artifact.size)}). `, fullButton()));
    }
    if (cloud || trajectory) scene = createScene(sceneHolder, { cloud, trajectory, title: loading && loading.name });
  };
  const main = (preferred && clouds.find((a) => a.name === (isPreview(preferred) ? fullCloudName(preferred) : preferred))) ||
    mainCloud(clouds, result);
  if (cloudSelect && main) cloudSelect.value = main.name;
  if (cloudSelect) cloudSelect.addEventListener('change', () => show(clouds.find((a) => a.name === cloudSelect.value)));
  if (!main) clear(status, el('p.muted', 'This job has no PLY point cloud.'));
  // A cloud named in the address (the viewer page's list) loads in full when it has no preview:
  // the user chose it, its size stated.
  await show(main, Boolean(preferred && main && main.name === preferred && !previews.has(main.name)));
  // A pair's "show in 3D" button: that pair's cloud in the viewer above.
  const viewCloud = (name) => {
    const artifact = clouds.find((a) => a.name === name);
    if (!artifact) return;
    if (cloudSelect) cloudSelect.value = name;
    sceneHolder.scrollIntoView({ behavior: 'smooth', block: 'center' });
    show(artifact);
  };
  clear(below,
    job.type === 'stereo_reconstruct' ? reconstructPairsCard(job, result, viewCloud) : null,
    trajectory && job.type === 'slam' ? el('div.card#top-view-card',
      el('h2', occupancy ? 'Top view: the trajectory over the occupancy grid' : 'Top view of the trajectory'),
      topView(trajectory, groundTruth, result, occupancy)) : null,
    summaryCard(result),
    await report ? statsCard(await report) : null);
  return () => scene && scene.dispose();
}

// The slam report's headline (the result's own figures): frames tracked, keyframes, loops, the
// errors against the ground truth when there is one, the frame rate. {card, text}.
export function slamHeadline(result) {
  const frames = Array.isArray(result.frames) ? result.frames.length : result.num_frames;
  if (!Number.isFinite(frames)) return null;
  const tracked = result.num_tracked;
  const loops = Array.isArray(result.loops) ? result.loops.length : null;
  const evaluation = result.evaluation;
  const rows = [
    ['frames-tracked', 'Frames tracked', `${tracked} of ${frames}` + (frames ? ` (${Math.round((100 * tracked) / frames)} %)` : '')],
    ['keyframes', 'Keyframes', String(result.num_keyframes ?? '–')],
    ['loops', 'Loop closures', loops === null ? '–' : String(loops)],
  ];
  if (evaluation) {
    rows.push(['ate', 'ATE (RMSE)', formatLength(evaluation.ate_rmse_m)]);
    rows.push(['rpe', 'RPE per frame (RMSE)', `${formatLength(evaluation.rpe_translation_rmse_m)}, ` +
      `${Number(evaluation.rpe_rotation_rmse_deg).toFixed(3)}°`]);
    const metre = (evaluation.rpe_segments || []).find((seg) => seg.length_m === 1 && seg.num_segments > 0);
    if (metre) {
      rows.push(['rpe-1m', 'RPE per 1 m (RMSE)', `${formatLength(metre.translation_rmse_m)} ` +
        `(${formatNumber(metre.translation_mean_percent, 2)} % mean), ${Number(metre.rotation_rmse_deg).toFixed(3)}°`]);
    }
    if (Number.isFinite(evaluation.final_drift_percent)) {
      rows.push(['drift', 'Final drift', `${formatNumber(evaluation.final_drift_percent, 2)} % of ${formatLength(evaluation.path_length_m)} travelled`]);
    }
  }
  rows.push(['frame-rate', 'Frame rate', `${formatNumber(result.frames_per_second, 2)} frames/s`]);
  const card = el('div.card#slam-headline', el('h2', 'SLAM'),
    el('dl.headline', rows.map(([key, label, value]) => el('div.headline-item', { dataset: { key } },
      el('dt', label), el('dd', value)))),
    evaluation ? null : el('p.muted#no-ground-truth', 'No ground truth was given: ATE and RPE need one (a .tum file of the dataset).'));
  const text = `${tracked} of ${frames} frames tracked, ${result.num_keyframes ?? '?'} keyframes, ` +
    `${loops ?? '?'} loop closure${loops === 1 ? '' : 's'}` +
    (evaluation ? `, ATE ${formatLength(evaluation.ate_rmse_m)}` : '') +
    `, ${formatNumber(result.frames_per_second, 2)} frames/s`;
  return { card, text };
}

// The occupancy grid of a slam job's dense map (ROS map_server: occupancy.pgm and its yaml), or
// null (parseOccupancy).
async function loadOccupancy(jobId, artifacts) {
  const pgm = pick(artifacts, /(^|\/)occupancy\.pgm$/i);
  const yaml = pick(artifacts, /(^|\/)occupancy\.yaml$/i);
  if (!pgm || !yaml) return null;
  try {
    const [bytes, text] = await Promise.all([fetchArtifactBytes(jobId, pgm.name), fetchArtifactText(jobId, yaml.name)]);
    return parseOccupancy(bytes, text);
  } catch (err) {
    console.warn('occupancy', err);
    return null;
  }
}

export { OCCUPANCY_COLOURS };

// The key of the occupancy grid's colours under a top view (`id` its element's).
export function occupancyKey(occupancy, id = 'occupancy-key') {
  const rgb = ([r, g, b]) => `rgb(${r}, ${g}, ${b})`;
  return colourKey({
    id,
    title: `Occupancy grid (cells of ${formatLength(occupancy.cell_m)}, ${occupancy.cols} × ${occupancy.rows}), seen from above in the world's x-y plane`,
    items: [
      { colour: rgb(OCCUPANCY_COLOURS.occupied), label: 'occupied: an obstacle' },
      { colour: rgb(OCCUPANCY_COLOURS.free), label: 'free: floor seen, nothing in the way' },
      { colour: rgb(OCCUPANCY_COLOURS.unknown), label: 'unknown: not seen' },
    ],
  });
}

// Downloads and parses a PLY artifact with a progress bar in `status`; null (and the error
// shown) when it cannot be read.
async function loadCloud(jobId, artifact, status) {
  const bar = el('div');
  clear(status, el('p.muted', `Loading ${artifact.name} (${formatBytes(artifact.size)})…`), bar);
  try {
    const bytes = await fetchArtifactBytes(jobId, artifact.name, (loaded, total) =>
      clear(bar, progressBar(total ? loaded / total : 0, `${formatBytes(loaded)} of ${formatBytes(total || artifact.size)}`)));
    const cloud = parsePly(bytes);
    clear(status);
    return cloud;
  } catch (err) {
    clear(status, errorBox(err, `Could not load ${artifact.name}`));
    return null;
  }
}

// SLAM: world_from_rig per frame. Stereo reconstruction: the rig itself, cam0 at the origin and
// cam1 at cam0_from_cam1 (from the relative_pose job the reconstruction used).
async function loadTrajectory(job, artifacts, result) {
  try {
    const json = pick(artifacts, /trajectory\.json$/i);
    if (json) return trajectoryFromJson(await fetchArtifactJson(job.id, json.name));
    const tum = pick(artifacts, /trajectory\.tum$/i);
    if (tum) return parseTum(await fetchArtifactText(job.id, tum.name));
    if (job.type === 'stereo_reconstruct' && result.clouds_merged && result.trajectory) {
      const placed = await placedPairPoses(job, result);
      if (placed && placed.length) return placed;
    }
    const rigJob = result.rig || (job.params && job.params.rig);
    if (job.type === 'stereo_reconstruct' && rigJob) {
      const rig = await get(`/jobs/${encodeURIComponent(rigJob)}/result`);
      const pose = rig.cam0_from_cam1;
      return [{ name: 'cam0', t: [0, 0, 0], q: [1, 0, 0, 0] }, { name: 'cam1', t: pose.translation_m, q: pose.rotation_wxyz }];
    }
  } catch (err) {
    console.warn('trajectory', err);
  }
  return null;
}

// The poses at which a stereo_reconstruct job placed its pairs in the merged cloud (api/stereo_job.h):
// from its slam job's trajectory, by frame name; or from the dataset's .tum file, by timestamp when
// the pairs are named by time, else one pose per pair in order. Each pose is named after its pair.
async function placedPairPoses(job, result) {
  const pairs = (result.pairs || []).filter((p) => p.placed);
  const source = String(result.trajectory.source || '');
  const base = (name) => String(name).replace(/^cam\d+\//, '').replace(/\.[^./]+$/, '');
  let poses;
  const sourceJob = /^[0-9a-f]{16}$/.exec(source.split(' ').pop());
  if (sourceJob) {
    const artifacts = await listArtifacts(sourceJob[0]);
    const json = pick(artifacts, /trajectory\.json$/i);
    if (!json) return null;
    const byName = new Map(trajectoryFromJson(await fetchArtifactJson(sourceJob[0], json.name)).map((p) => [base(p.name), p]));
    poses = pairs.map((pair) => byName.get(base(pair.name)));
  } else {
    const response = await fetchWithAuth(imageUrl(job.dataset ?? job.dataset_id, source));
    const stamped = parseTum(await response.text());
    const times = pairs.map((p) => Number(base(p.name)));
    poses = times.every(Number.isFinite)
      ? times.map((t) => stamped.reduce((best, p) => (Math.abs(Number(p.name) - t) < Math.abs(Number(best.name) - t) ? p : best), stamped[0]))
      : pairs.map((_, i) => stamped[i]);
  }
  return poses.map((p, i) => p && { ...p, name: pairs[i].name, pairPose: true }).filter(Boolean);
}

// The ground truth: the dataset's TUM file named by params.ground_truth, else an artifact.
// Returned in the estimate's frame (through evaluation.gt_from_estimate) so that the two overlay.
async function loadGroundTruth(job, artifacts, result) {
  try {
    let poses = null;
    const file = job.params && job.params.ground_truth;
    if (file) {
      const response = await fetchWithAuth(imageUrl(job.dataset ?? job.dataset_id, file)).catch(() => null);
      if (response) poses = parseTum(await response.text());
    }
    const a = artifacts.find((x) => /ground.?truth/i.test(x.name) && /\.(tum|txt|json)$/i.test(x.name));
    if (!poses && a) {
      poses = /\.json$/i.test(a.name) ? trajectoryFromJson(await fetchArtifactJson(job.id, a.name))
        : parseTum(await fetchArtifactText(job.id, a.name));
    }
    const gtFromEstimate = result.evaluation && result.evaluation.gt_from_estimate;
    return poses && gtFromEstimate ? transformTrajectory(poses, inversePose(gtFromEstimate)) : poses;
  } catch (err) {
    console.warn('ground truth', err);
    return null;
  }
}

// The per-frame (slam) or per-pair (stereo_reconstruct) statistics: in the result, or report.json.
async function loadReport(jobId, artifacts, result) {
  if (Array.isArray(result.frames) || Array.isArray(result.pairs)) return result;
  const a = pick(artifacts, /report\.json$/i);
  if (!a) return null;
  try {
    return await fetchArtifactJson(jobId, a.name);
  } catch (_) {
    return null;
  }
}

// The top view with its legend: the estimate coloured by each frame's state (lost frames leave a
// gap), a line per loop closure between its two keyframes, the ground truth when given. Results
// from before loops and states were reported draw as one tracked line.
function topView(trajectory, groundTruth, result, occupancy) {
  const canvas = el('canvas.topview#top-view', { width: 560, height: 560 });
  requestAnimationFrame(() => drawTopView(canvas, trajectory, groundTruth, result.loops, occupancy, OCCUPANCY_COLOURS));
  const frames = (n) => `${n} frame${n === 1 ? '' : 's'}`;
  const count = (state) => trajectory.filter((p) => (p.state === 'initialised' ? 'tracked' : p.state || 'tracked') === state).length;
  // Frames without a pose: those the trajectory skips, and any after its last pose.
  const last = trajectory.length ? trajectory[trajectory.length - 1].index ?? trajectory.length - 1 : -1;
  const lost = Math.max(Array.isArray(result.frames) ? result.frames.length : 0, last + 1) - trajectory.length;
  const item = (key, colour, text, line = true) => el('li.legend-item', { dataset: { key } },
    el(line ? 'span.swatch' : 'span.swatch.gap', { style: line ? `background: ${colour}` : undefined }), text);
  const loops = Array.isArray(result.loops) ? loopSegments(trajectory, result.loops).length : null;
  return el('div', canvas, occupancy ? occupancyKey(occupancy) : null, el('ul.legend#top-view-legend',
    Object.entries(STATE_COLOURS).map(([state, colour]) => item(state, colour, `${state} (${frames(count(state))})`)),
    item('lost', '', `lost: a gap in the line (${frames(lost)})`, false),
    loops === null ? null : item('loop', LOOP_COLOUR, `loop closure: joins its two keyframes (${loops})`),
    groundTruth ? item('ground-truth', GROUND_TRUTH_COLOUR, 'ground truth') : null),
  groundTruth ? el('p.muted', 'The ground truth is brought into the estimate\'s frame by the evaluation\'s alignment when there is one.')
    : el('p.muted', 'No ground truth was given.'));
}

// A result object's plain values as a list of labels and values with units; `unit` is the unit
// its parent key names (timings_s: every entry in seconds). Poses and lists are left to the
// views that draw them.
function valueList(object, unit = '') {
  const rows = Object.entries(object || {}).filter(([, v]) => v !== null && (typeof v !== 'object' ||
    (Array.isArray(v) && v.length <= 3 && v.every((x) => typeof x === 'number'))));
  return el('dl.kv', rows.map(([k, v]) => {
    const described = describeKey(k);
    const key = unit && !described.unit ? `${k}_${unit}` : k;
    const text = Array.isArray(v) ? `${v.map((x) => formatNumber(x, 3)).join(' × ')}${described.unit ? ` ${described.unit}` : ''}`
      : typeof v === 'boolean' ? (v ? 'yes' : 'no') : formatWithUnit(key, v);
    return [el('dt', described.label), el('dd', { dataset: { key: k } }, text)];
  }));
}

// The result's own figures, labelled, with units: counts and rates, then each group (the
// evaluation, the dense map, the input, the timings) in its own list.
const GROUPS = {
  evaluation: ['Evaluation against the ground truth', ''],
  dense_map: ['Dense map and occupancy grid', ''],
  input: ['Input', ''],
  timings_s: ['Time per stage (wall)', 's'],
  cpu_timings_s: ['Time per stage (CPU)', 's'],
  global_bundle_adjustment: ['Global bundle adjustment', ''],
  options: ['Options', ''],
  grid: ['Dense grid', ''],
};
function summaryCard(result) {
  const top = Object.fromEntries(Object.entries(result || {}).filter(([, v]) => typeof v === 'number' || typeof v === 'string'));
  const groups = Object.entries(GROUPS).filter(([k]) => result && result[k] && typeof result[k] === 'object' && !Array.isArray(result[k]));
  if (!Object.keys(top).length && !groups.length) return null;
  return el('div.card#result-summary', el('h2', 'Summary'), valueList(top),
    groups.map(([k, [title, unit]]) => el('details', { dataset: { group: k } }, el('summary', title), valueList(result[k], unit))));
}

// Per-frame (or per-pair) statistics: a table with the scalar fields of report.frames (pairs).
function statsCard(report) {
  const frames = report.frames || report.pairs || [];
  const what = report.frames ? 'frame' : 'pair';
  if (!frames.length) return null;
  // Columns: scalars and arrays of numbers that some frame has a value for; name and state first.
  const columns = [];
  for (const frame of frames.slice(0, 50)) {
    for (const [k, v] of Object.entries(frame)) {
      const shown = (typeof v !== 'object' && v !== '') || (Array.isArray(v) && v.length && v.every((x) => typeof x === 'number'));
      if (!columns.includes(k) && shown) columns.push(k);
    }
  }
  const rank = (c) => ['name', 'state', 'reason'].indexOf(c) >>> 0;  // -1 becomes large
  columns.sort((a, b) => rank(a) - rank(b));
  const shown = frames.slice(0, 1000);
  return el('div.card#frame-stats', el('h2', `Per-${what} statistics (${frames.length} ${what}s)`),
    el('div.table-scroll', { style: 'max-height: 420px; overflow-y: auto' }, el('table',
      el('thead', el('tr', columns.map((c) => {
        const { label, unit } = describeKey(c);
        return el(frames.some((f) => typeof f[c] === 'number' || Array.isArray(f[c])) ? 'th.num' : 'th', { title: c },
          unit ? `${label} (${unit})` : label);
      }))),
      el('tbody', shown.map((f) => el('tr', columns.map((c) => frameCell(f[c], c))))))),
    frames.length > shown.length ? el('p.muted', `First ${shown.length} ${what}s shown.`) : null);
}

function frameCell(value, column) {
  if (column === 'reason') return el('td.reason', value ?? '');
  const number = (x) => (Number.isInteger(x) ? String(x) : formatNumber(x, 3));
  if (Array.isArray(value)) return el('td.num', value.map(number).join(' / '));
  if (typeof value === 'number') return el('td.num', number(value));
  return el('td', value ?? '');
}

// ---- the three.js scene ----------------------------------------------------------------------

// A robust centre and radius of the cloud (points far away would otherwise make it a dot).
function robustBounds(positions, count) {
  const step = Math.max(1, Math.floor(count / 20000));
  const xs = [[], [], []];
  for (let i = 0; i < count; i += step) for (let k = 0; k < 3; k += 1) xs[k].push(positions[3 * i + k]);
  const centre = xs.map((a) => {
    a.sort((p, q) => p - q);
    return a[Math.floor(a.length / 2)] || 0;
  });
  const distances = [];
  for (let i = 0; i < xs[0].length; i += 1) distances.push(Math.hypot(xs[0][i] - centre[0], xs[1][i] - centre[1], xs[2][i] - centre[2]));
  distances.sort((p, q) => p - q);
  const radius = distances[Math.floor(distances.length * 0.9)] || 1;
  return { centre: new THREE.Vector3(...centre), radius: Math.max(radius, 1e-3) };
}

const PREVIEW_POINTS = 250000;

// Every k-th point, so that about `target` remain.
function subsample(cloud, target) {
  const step = Math.ceil(cloud.count / target);
  const count = Math.floor((cloud.count - 1) / step) + 1;
  const positions = new Float32Array(3 * count);
  const colors = cloud.colors ? new Uint8Array(3 * count) : null;
  for (let i = 0, j = 0; j < count; i += step, j += 1) {
    positions.set(cloud.positions.subarray(3 * i, 3 * i + 3), 3 * j);
    if (colors) colors.set(cloud.colors.subarray(3 * i, 3 * i + 3), 3 * j);
  }
  return { count, positions, colors, step };
}

function pointCloudObject(cloud, size) {
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(cloud.positions, 3));
  if (cloud.colors) geometry.setAttribute('color', new THREE.BufferAttribute(cloud.colors, 3, true));
  const material = new THREE.PointsMaterial({ size, sizeAttenuation: false, vertexColors: !!cloud.colors,
    color: cloud.colors ? 0xffffff : 0x9ecbff });
  return new THREE.Points(geometry, material);
}

// The trajectory as a line and each rig pose as small axes (x red, y green, z blue), all in two
// geometries whatever the number of frames.
function trajectoryObjects(trajectory, axisLength) {
  const group = new THREE.Group();
  const path = new Float32Array(trajectory.length * 3);
  const axes = new Float32Array(trajectory.length * 18);
  const colors = new Float32Array(trajectory.length * 18);
  const palette = [[1, 0.25, 0.25], [0.3, 1, 0.3], [0.35, 0.55, 1]];
  trajectory.forEach((pose, i) => {
    const t = new THREE.Vector3(...pose.t);
    const q = new THREE.Quaternion(pose.q[1], pose.q[2], pose.q[3], pose.q[0]);  // three.js: (x, y, z, w)
    path.set(pose.t, 3 * i);
    for (let k = 0; k < 3; k += 1) {
      const tip = new THREE.Vector3(k === 0 ? 1 : 0, k === 1 ? 1 : 0, k === 2 ? 1 : 0).multiplyScalar(axisLength).applyQuaternion(q).add(t);
      axes.set([t.x, t.y, t.z, tip.x, tip.y, tip.z], 18 * i + 6 * k);
      colors.set([...palette[k], ...palette[k]], 18 * i + 6 * k);
    }
  });
  const line = new THREE.BufferGeometry();
  line.setAttribute('position', new THREE.BufferAttribute(path, 3));
  group.add(new THREE.Line(line, new THREE.LineBasicMaterial({ color: 0xfacc15 })));
  const poses = new THREE.BufferGeometry();
  poses.setAttribute('position', new THREE.BufferAttribute(axes, 3));
  poses.setAttribute('color', new THREE.BufferAttribute(colors, 3));
  group.add(new THREE.LineSegments(poses, new THREE.LineBasicMaterial({ vertexColors: true })));
  return group;
}

// The scene's objects: the cloud, its subsample drawn while the view moves, the trajectory.
function sceneContent(cloud, trajectory) {
  const scene = new THREE.Scene();
  const positionsForBounds = cloud && cloud.count ? cloud : trajectory && {
    positions: Float32Array.from(trajectory.flatMap((p) => p.t)), count: trajectory.length };
  const { centre, radius } = positionsForBounds ? robustBounds(positionsForBounds.positions, positionsForBounds.count)
    : { centre: new THREE.Vector3(), radius: 1 };
  const points = cloud ? pointCloudObject(cloud, 2) : null;
  if (points) scene.add(points);
  const sub = cloud && cloud.count > PREVIEW_POINTS ? subsample(cloud, PREVIEW_POINTS) : null;
  const preview = sub ? pointCloudObject(sub, 2) : null;
  if (preview) {
    preview.userData.step = sub.step;
    preview.visible = false;
    scene.add(preview);
  }
  const path = trajectory && trajectory.length ? trajectoryObjects(trajectory, radius * 0.04) : null;
  if (path) scene.add(path);
  return { scene, points, preview, path, centre, radius };
}

// Gives a cloud object (and its subsample, every `step`-th point) new colours (RGB bytes).
function setColours(object, colours, step = 1) {
  if (!object) return;
  const count = object.geometry.attributes.position.count;
  const own = step === 1 ? colours : new Uint8Array(3 * count);
  if (step !== 1) for (let j = 0; j < count; j += 1) own.set(colours.subarray(3 * j * step, 3 * j * step + 3), 3 * j);
  object.geometry.setAttribute('color', new THREE.BufferAttribute(own, 3, true));
  object.material.vertexColors = true;
  object.material.color.set(0xffffff);
  object.material.needsUpdate = true;
}

// "Colour by": the cloud's own colours, height along the up axis, range from the origin or
// confidence (when the PLY has it), with the colour bar of the values shown. Returns
// {control, setUp}; the bar goes into `barHolder`.
function colourControl(cloud, { points, preview }, barHolder, requestDraw) {
  const modes = colourModes(cloud);
  let up = [0, -1, 0];
  const select = el('select#colour-by', modes.map((m) => el('option', { value: m.mode }, m.label)));
  const apply = () => {
    const mode = modes.find((m) => m.mode === select.value);
    if (mode.mode === 'rgb') {
      setColours(points, cloud.colors);
      setColours(preview, cloud.colors, preview && preview.userData.step);
      clear(barHolder);
    } else {
      const values = pointValues(cloud, mode.mode, up);
      const range = mode.mode === 'confidence' ? [0, 1] : percentileRange(values);
      const colours = turboColours(values, range);
      setColours(points, colours);
      setColours(preview, colours, preview && preview.userData.step);
      clear(barHolder, colourBar({ colourAt: (t) => TURBO[Math.round(255 * t)], min: range[0], max: range[1], unit: mode.unit,
        title: `Points coloured by ${mode.label}${mode.mode === 'height' ? ` (along ${upName(up)})` : ''}`, id: 'cloud-colour-bar' }));
    }
    barHolder.dataset.mode = mode.mode;
    requestDraw();
  };
  select.addEventListener('change', apply);
  if (!cloud.colors) apply();  // no colours of its own: by height from the start
  return {
    control: el('label', 'colour by', select),
    setUp(next) {
      up = next;
      if (select.value === 'height') apply();
    },
  };
}

const upName = ([x, y, z]) => `${x + y + z < 0 ? '−' : '+'}${x ? 'x' : y ? 'y' : 'z'}`;

// The controls over the scene: point size, up axis, trajectory on/off.
function hudControls(view, { points, preview, path }, trajectory) {
  const sizeInput = el('input#point-size', { type: 'range', min: 1, max: 12, step: 0.5, value: 2,
    oninput: (e) => {
      for (const cloudObject of [points, preview]) if (cloudObject) cloudObject.material.size = Number(e.target.value);
      view.requestDraw();
    } });
  const upSelect = el('select#up-axis', { onchange: (e) => view.setUp(e.target.value.split(',').map(Number)) },
    el('option', { value: '0,-1,0' }, '−y (camera frames)'), el('option', { value: '0,0,1' }, '+z'), el('option', { value: '0,1,0' }, '+y'));
  const pathToggle = el('input', { type: 'checkbox', checked: true,
    onchange: (e) => {
      path.visible = e.target.checked;
      view.requestDraw();
    } });
  // What the poses are: a slam trajectory, the pairs a reconstruction placed, or the rig alone.
  const poses = !trajectory ? '' : trajectory.some((p) => p.pairPose) ? `pair poses (${trajectory.length} placed)`
    : trajectory.length === 2 && trajectory[0].name === 'cam0' && trajectory[1].name === 'cam1' ? 'the rig: cam0 and cam1'
      : `trajectory (${trajectory.length} poses)`;
  return [el('label', 'point size', sizeInput), el('label', 'up', upSelect),
    path ? el('label#pose-toggle', pathToggle, poses) : null,
    el('span.muted', 'drag: orbit · right-drag: pan · wheel: zoom')].filter(Boolean);
}

// Creates the viewer in `holder`; returns {dispose}. Draws only when something changed; while
// the view moves (mouse held down) it draws the subsample, and the full cloud when released.
export function createScene(holder, { cloud, trajectory, title }) {
  const box = el('div.viewer#viewer');
  const hud = el('div.hud');
  const barHolder = el('div#cloud-colour');
  box.append(hud);
  holder.append(box, barHolder);
  const renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
  renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
  renderer.setClearColor(0x0b0f17);
  box.prepend(renderer.domElement);
  const content = sceneContent(cloud, trajectory);
  const { scene, points, preview, centre, radius } = content;
  const camera = new THREE.PerspectiveCamera(60, 1, radius / 1000, radius * 1000);
  camera.up.set(0, -1, 0);  // omnirig's frames are camera-like: y points down
  camera.position.copy(centre).add(new THREE.Vector3(0, -radius * 0.8, -radius * 1.6));

  const stats = el('span.mono');
  let frameRequested = false;
  const draw = () => {
    frameRequested = false;
    renderer.render(scene, camera);
    stats.textContent = `${cloud ? cloud.count.toLocaleString() : 0} points` +
      (preview && preview.visible ? ` (${preview.geometry.attributes.position.count.toLocaleString()} while moving)` : '');
    box.dataset.frames = String(Number(box.dataset.frames || 0) + 1);
  };
  const requestDraw = () => {
    if (!frameRequested) {
      frameRequested = true;
      requestAnimationFrame(draw);
    }
  };
  const setMoving = (moving) => {
    if (!preview) return;
    preview.visible = moving;
    points.visible = !moving;
    requestDraw();
  };
  // OrbitControls takes the camera's up axis when made, so "up" makes them again.
  let controls = null;
  const makeControls = (target) => {
    if (controls) controls.dispose();
    controls = new OrbitControls(camera, renderer.domElement);
    controls.screenSpacePanning = true;
    controls.target.copy(target);
    controls.addEventListener('change', requestDraw);
    controls.addEventListener('start', () => setMoving(true));
    controls.addEventListener('end', () => setMoving(false));
    controls.update();
  };
  makeControls(centre);
  const colouring = cloud && cloud.count ? colourControl(cloud, content, barHolder, requestDraw) : null;
  const setUp = ([x, y, z]) => {
    if (colouring) colouring.setUp([x, y, z]);
    camera.up.set(x, y, z);
    makeControls(controls.target.clone());
    requestDraw();
  };

  const resize = () => {
    const w = box.clientWidth || 800;
    const h = box.clientHeight || 500;
    renderer.setSize(w, h, false);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    requestDraw();
  };
  const observer = new ResizeObserver(resize);
  observer.observe(box);
  hud.append(el('strong', title || 'scene'), stats, ...hudControls({ requestDraw, setUp }, content, trajectory),
    ...(colouring ? [colouring.control] : []));
  resize();
  // For tests and curious users: one synchronous draw, waiting for the GPU to finish it.
  box.measureDrawMs = (moving = false) => {
    setMoving(moving);
    const start = performance.now();
    renderer.render(scene, camera);
    const gl = renderer.getContext();
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));  // waits for the draw
    return performance.now() - start;
  };
  return {
    renderer,
    dispose() {
      observer.disconnect();
      controls.dispose();
      scene.traverse((o) => {
        if (o.geometry) o.geometry.dispose();
        if (o.material) o.material.dispose();
      });
      renderer.dispose();
    },
  };
}
