// The 3D viewer (SLAM and stereo reconstruction): the coloured point cloud, the trajectory and
// the rig poses with orbit, pan, zoom and a point size control; a top view of the trajectory
// against the ground truth when there is one; the per-frame statistics.
// #/viewer/JOB_ID shows a job's artifacts; #/viewer alone opens a local PLY file.
//
// Stays responsive with millions of points: one BufferGeometry with typed arrays straight from the
// PLY parser, one Points draw call, and rendering only when the view changes.

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { fetchArtifactBytes, fetchArtifactJson, fetchArtifactText, fetchWithAuth, get, imageUrl } from './api.js';
import { listArtifacts, renderArtifacts } from './artifacts.js';
import { parsePly } from './ply.js';
import { reconstructPairsCard } from './reconstruct_report.js';
import {
  drawTopView, GROUND_TRUTH_COLOUR, inversePose, LOOP_COLOUR, loopSegments, parseTum, STATE_COLOURS,
  trajectoryFromJson, transformTrajectory,
} from './topview.js';
import { clear, el, errorBox, formatBytes, formatNumber, progressBar } from './ui.js';

export async function render(view, id) {
  if (id) {
    const job = await get(`/jobs/${encodeURIComponent(id)}`);
    const report = el('div');
    const artifacts = el('div.card#artifacts');
    clear(view, el('p', el('a', { href: `#/jobs/${encodeURIComponent(id)}` }, `← job ${id}`)),
      el('h1', `3D viewer: job ${id} (${job.type})`), report, artifacts);
    const cleanup = await renderJobReport(report, job);
    await renderArtifacts(artifacts, id);
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
  clear(view, el('h1', '3D viewer'),
    el('div.card', el('p', 'Open a job\'s 3D results from its page (Jobs → a slam or stereo_reconstruct job), ' +
      'or a PLY point cloud from this computer: ', input)), holder);
  return () => scene && scene.dispose();
}

// ---- a job's results -------------------------------------------------------------------------

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

// Shown under a succeeded slam or stereo_reconstruct job. Returns a cleanup function.
export async function renderJobReport(container, job) {
  const artifacts = await listArtifacts(job.id);
  const result = await get(`/jobs/${encodeURIComponent(job.id)}/result`).catch(() => ({}));
  const clouds = artifacts.filter((a) => /\.ply$/i.test(a.name));
  const status = el('div');
  const sceneHolder = el('div');
  const below = el('div');
  const cloudSelect = clouds.length > 1 ? el('select#cloud-select', clouds.map((a) =>
    el('option', { value: a.name }, `${a.name} (${formatBytes(a.size)})`))) : null;
  clear(container, el('div.card', el('h2', 'Point cloud and trajectory'),
    cloudSelect ? el('p', 'Cloud: ', cloudSelect) : null, status, sceneHolder), below);

  const [trajectory, groundTruth, report] = await Promise.all([
    loadTrajectory(job, artifacts, result), loadGroundTruth(job, artifacts, result), Promise.resolve(loadReport(job.id, artifacts, result))]);
  let scene = null;
  let shown = 0;  // the latest request: an earlier load that finishes later is dropped
  const show = async (artifact) => {
    const request = ++shown;
    if (scene) scene.dispose();
    scene = null;
    clear(sceneHolder);
    const cloud = artifact ? await loadCloud(job.id, artifact, status) : null;
    if (request !== shown) return;
    if (cloud || trajectory) scene = createScene(sceneHolder, { cloud, trajectory, title: artifact && artifact.name });
  };
  const main = mainCloud(artifacts, result);
  if (cloudSelect && main) cloudSelect.value = main.name;
  if (cloudSelect) cloudSelect.addEventListener('change', () => show(clouds.find((a) => a.name === cloudSelect.value)));
  if (!main) clear(status, el('p.muted', 'This job has no PLY point cloud.'));
  await show(main);
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
    trajectory && job.type === 'slam' ? el('div.card#top-view-card', el('h2', 'Top view of the trajectory'), topView(trajectory, groundTruth, result)) : null,
    summaryCard(result),
    await report ? statsCard(await report) : null);
  return () => scene && scene.dispose();
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
function topView(trajectory, groundTruth, result) {
  const canvas = el('canvas.topview#top-view', { width: 560, height: 560 });
  requestAnimationFrame(() => drawTopView(canvas, trajectory, groundTruth, result.loops));
  const frames = (n) => `${n} frame${n === 1 ? '' : 's'}`;
  const count = (state) => trajectory.filter((p) => (p.state === 'initialised' ? 'tracked' : p.state || 'tracked') === state).length;
  // Frames without a pose: those the trajectory skips, and any after its last pose.
  const last = trajectory.length ? trajectory[trajectory.length - 1].index ?? trajectory.length - 1 : -1;
  const lost = Math.max(Array.isArray(result.frames) ? result.frames.length : 0, last + 1) - trajectory.length;
  const item = (key, colour, text, line = true) => el('li.legend-item', { dataset: { key } },
    el(line ? 'span.swatch' : 'span.swatch.gap', { style: line ? `background: ${colour}` : undefined }), text);
  const loops = Array.isArray(result.loops) ? loopSegments(trajectory, result.loops).length : null;
  return el('div', canvas, el('ul.legend#top-view-legend',
    Object.entries(STATE_COLOURS).map(([state, colour]) => item(state, colour, `${state} (${frames(count(state))})`)),
    item('lost', '', `lost: a gap in the line (${frames(lost)})`, false),
    loops === null ? null : item('loop', LOOP_COLOUR, `loop closure: joins its two keyframes (${loops})`),
    groundTruth ? item('ground-truth', GROUND_TRUTH_COLOUR, 'ground truth') : null),
  groundTruth ? el('p.muted', 'The ground truth is brought into the estimate\'s frame by the evaluation\'s alignment when there is one.')
    : el('p.muted', 'No ground truth was given.'));
}

// The scalar metrics of the result (ATE, RPE, drift, counts) as a list.
function summaryCard(result) {
  const rows = Object.entries(result || {}).filter(([, v]) => typeof v === 'number' || typeof v === 'string');
  const nested = Object.entries(result || {}).filter(([k, v]) => v && typeof v === 'object' && !Array.isArray(v) &&
    /eval|metric|ate|rpe|drift|summary/i.test(k));
  if (!rows.length && !nested.length) return null;
  return el('div.card#result-summary', el('h2', 'Summary'),
    el('dl.kv', rows.map(([k, v]) => [el('dt.mono', k), el('dd', typeof v === 'number' && !Number.isInteger(v) ? formatNumber(v, 4) : String(v))])),
    nested.map(([k, v]) => el('details', el('summary', k), el('pre.mono', JSON.stringify(v, null, 2)))));
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
      el('thead', el('tr', columns.map((c) => el(frames.some((f) => typeof f[c] === 'number' || Array.isArray(f[c])) ? 'th.num' : 'th', c)))),
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
  return { count, positions, colors };
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
  const preview = cloud && cloud.count > PREVIEW_POINTS ? pointCloudObject(subsample(cloud, PREVIEW_POINTS), 2) : null;
  if (preview) {
    preview.visible = false;
    scene.add(preview);
  }
  const path = trajectory && trajectory.length ? trajectoryObjects(trajectory, radius * 0.04) : null;
  if (path) scene.add(path);
  return { scene, points, preview, path, centre, radius };
}

// The controls over the scene: point size, up axis, trajectory on/off.
function hudControls(view, { points, preview, path }, trajectory) {
  const sizeInput = el('input#point-size', { type: 'range', min: 1, max: 12, step: 0.5, value: 2,
    oninput: (e) => {
      for (const cloudObject of [points, preview]) if (cloudObject) cloudObject.material.size = Number(e.target.value);
      view.requestDraw();
    } });
  const upSelect = el('select', { onchange: (e) => view.setUp(e.target.value.split(',').map(Number)) },
    el('option', { value: '0,-1,0' }, '−y (camera frames)'), el('option', { value: '0,0,1' }, '+z'), el('option', { value: '0,1,0' }, '+y'));
  const pathToggle = el('input', { type: 'checkbox', checked: true,
    onchange: (e) => {
      path.visible = e.target.checked;
      view.requestDraw();
    } });
  return [el('label', 'point size', sizeInput), el('label', 'up', upSelect),
    path ? el('label', pathToggle, `trajectory and rig poses (${trajectory.length})`) : null,
    el('span.muted', 'drag: orbit · right-drag: pan · wheel: zoom')].filter(Boolean);
}

// Creates the viewer in `holder`; returns {dispose}. Draws only when something changed; while
// the view moves (mouse held down) it draws the subsample, and the full cloud when released.
export function createScene(holder, { cloud, trajectory, title }) {
  const box = el('div.viewer#viewer');
  const hud = el('div.hud');
  box.append(hud);
  holder.append(box);
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
  const setUp = ([x, y, z]) => {
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
  hud.append(el('strong', title || 'scene'), stats, ...hudControls({ requestDraw, setUp }, content, trajectory));
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
