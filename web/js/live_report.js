// The page of a live slam job while it runs (params.live): the trajectory and the map growing as
// the robot sends its frames, the frame rate, the latency from receipt to pose, the frames
// skipped, the share placed in a saved map when the job localises in one, and with a dense map
// (params.dense_map) the occupancy grid so far under the trajectory, as the finished page draws
// it. Frames arrive as the server's `frame` events (GET /api/v1/events?job=ID); trajectory.json
// and map.ply, and occupancy.pgm and occupancy.yaml, which the server refreshes while the job
// runs, are read again every few seconds (they carry the map's corrections) and the grid at once
// when its `artifacts` event tells of a new one. Without events (a server with a token) the page
// reads those files only.

import { API, fetchArtifactBytes, fetchArtifactJson, fetchArtifactText, getToken, post } from './api.js';
import { parsePly } from './ply.js';
import { drawTopView, OCCUPANCY_COLOURS, parseOccupancy, trajectoryFromJson } from './topview.js';
import { clear, el, errorBox, formatNumber } from './ui.js';

export const isLiveSlam = (job) => job.type === 'slam' && Boolean(job.params && job.params.live === true);

const REFRESH_MS = 2000;  // the server refreshes the running job's files at least this often
const RATE_WINDOW_S = 10;  // the frame rate over the last seconds of capture time
const LATENCY_WINDOW = 200;  // the latency percentiles over the last frames

// The nearest-rank percentile p (0..100) of `values`, NaN when there are none.
export function percentile(values, p) {
  if (!values.length) return NaN;
  const sorted = [...values].sort((a, b) => a - b);
  return sorted[Math.min(sorted.length - 1, Math.max(0, Math.ceil((p / 100) * sorted.length) - 1))];
}

// The figures of a live run from its frame events ({frame_index, stamp_s, state, keyframe,
// in_map, world_from_rig, latency_ms, num_skipped}, any order): frames received (tracked, lost
// and skipped), the tracking rate in frames per second of capture time over the last
// RATE_WINDOW_S seconds, the latency p50 / p95 over the last LATENCY_WINDOW frames, keyframes,
// and frames placed in the saved map.
export function liveFigures(events) {
  const frames = [...events].sort((a, b) => a.frame_index - b.frame_index);
  const skipped = frames.reduce((m, f) => Math.max(m, f.num_skipped || 0), 0);
  const posed = frames.filter((f) => f.world_from_rig);
  const stamps = frames.map((f) => f.stamp_s).filter(Number.isFinite);
  let rateHz = NaN;
  if (stamps.length >= 2) {
    const last = stamps[stamps.length - 1];
    const recent = stamps.filter((s) => s >= last - RATE_WINDOW_S);
    if (recent.length >= 2 && last > recent[0]) rateHz = (recent.length - 1) / (last - recent[0]);
  }
  const latencies = frames.slice(-LATENCY_WINDOW).map((f) => f.latency_ms).filter(Number.isFinite);
  return {
    received: frames.length + skipped,
    tracked: posed.length,
    lost: frames.length - posed.length,
    skipped,
    keyframes: frames.filter((f) => f.keyframe).length,
    inMap: frames.filter((f) => f.in_map).length,
    rateHz,
    latencyP50Ms: percentile(latencies, 50),
    latencyP95Ms: percentile(latencies, 95),
  };
}

// The trajectory to draw: the server's trajectory.json (poses as the map holds them now), then
// the poses of frames that arrived after it was written, from their events.
export function liveTrajectory(trajectoryJson, events) {
  const base = trajectoryJson ? trajectoryFromJson(trajectoryJson) : [];
  const known = trajectoryJson && Array.isArray(trajectoryJson.frames) ? trajectoryJson.frames.length : 0;
  const newer = [...events].filter((f) => f.frame_index >= known && f.world_from_rig)
    .sort((a, b) => a.frame_index - b.frame_index)
    .map((f) => ({ name: f.name, index: f.frame_index, state: f.state, gap: false,
      t: f.world_from_rig.translation_m, q: f.world_from_rig.rotation_wxyz }));
  return [...base, ...newer];
}

function headline(figures, localising) {
  const ms = (x) => (Number.isFinite(x) ? `${formatNumber(x, 1)} ms` : '–');
  const rows = [
    ['frames-received', 'Frames received', String(figures.received)],
    ['frames-tracked', 'Frames tracked', String(figures.tracked)],
    ['frames-skipped', 'Frames skipped', `${figures.skipped} (arrived while tracking was busy)`],
    ['frame-rate', 'Frame rate', Number.isFinite(figures.rateHz) ? `${formatNumber(figures.rateHz, 1)} frames/s` : '–'],
    ['latency', 'Latency, receipt to pose', `p50 ${ms(figures.latencyP50Ms)}, p95 ${ms(figures.latencyP95Ms)}`],
    ['keyframes', 'Keyframes', String(figures.keyframes)],
  ];
  if (figures.lost) rows.push(['frames-lost', 'Frames lost', String(figures.lost)]);
  if (localising) {
    const share = figures.tracked ? Math.round((100 * figures.inMap) / figures.tracked) : 0;
    rows.push(['in-map', 'In the saved map', `${figures.inMap} of ${figures.tracked} frames (${share} %)`]);
  }
  return el('dl.headline', rows.map(([key, label, value]) => el('div.headline-item', { dataset: { key } },
    el('dt', label), el('dd', value))));
}

// Shows the live job in `container` until the returned cleanup function is called (the page
// calls it when the job ends and shows the finished report instead).
export function renderLiveReport(container, job) {
  const events = new Map();  // frame_index -> its event
  let trajectoryJson = null;
  let mapBytes = 0;
  let scene = null;
  let stopped = false;
  let occupancy = null;  // the grid so far (with a dense map)
  let occupancyFiles = null;  // its yaml and PGM bytes, to redraw only when they changed
  const dense = Boolean(job.params && job.params.dense_map);
  const figures = el('div#live-figures');
  const occupancyHolder = el('div#live-occupancy');
  const canvas = el('canvas.topview#live-top-view', { width: 560, height: 560 });
  const mapNote = el('p.muted#live-map-note', 'Waiting for the first frames…');
  const sceneHolder = el('div#live-map');
  const problem = el('div');
  const finish = el('button#live-finish', { type: 'button', onclick: async () => {
    finish.disabled = true;
    try {
      await post(`/jobs/${encodeURIComponent(job.id)}/finish`);
      finish.textContent = 'Finishing: closing loops and the global adjustment…';
    } catch (err) {
      finish.disabled = false;
      clear(problem, errorBox(err, 'Could not finish the run'));
    }
  } }, 'Finish the run');
  const localising = Boolean(job.params && job.params.map);
  clear(container,
    el('div.card#live-card', el('h2', 'Live: the trajectory and the map as the robot sends its frames'),
      figures,
      el('p.muted', localising ? `Localising in the saved map of job ${job.params.map}. ` : '',
        'The trajectory and the map are redrawn as frames arrive; the poses of earlier frames move as the map is adjusted.',
        dense ? ' The occupancy grid under it grows as keyframes are fused (made again from the final poses when the run ends).' : ''),
      canvas, occupancyHolder, el('p', finish), problem),
    el('div.card', el('h2', 'The map so far'), mapNote, sceneHolder));
  const redraw = () => {
    const list = [...events.values()];
    clear(figures, headline(liveFigures(list), localising));
    const trajectory = liveTrajectory(trajectoryJson, list);
    canvas.dataset.poses = String(trajectory.length);
    drawTopView(canvas, trajectory, null, [], occupancy, OCCUPANCY_COLOURS);
  };
  redraw();

  let source = null;
  if (typeof EventSource !== 'undefined' && !getToken()) {
    source = new EventSource(`${API}/events?job=${encodeURIComponent(job.id)}`);
    source.addEventListener('frame', (e) => {
      try {
        const frame = JSON.parse(e.data);
        if (Number.isInteger(frame.frame_index)) events.set(frame.frame_index, frame);
      } catch (_) {
        return;  // a malformed event: the next refresh of trajectory.json shows the truth
      }
      redraw();
    });
    if (dense) {
      source.addEventListener('artifacts', (e) => {
        try {
          if (JSON.parse(e.data).artifacts.includes('occupancy.pgm')) refreshOccupancy();
        } catch (_) {
          // a malformed event: the next refresh reads the grid
        }
      });
    }
  }
  // The grid so far: drawn under the trajectory, with the key of its colours.
  const refreshOccupancy = async () => {
    try {
      const text = await fetchArtifactText(job.id, 'occupancy.yaml');
      const bytes = await fetchArtifactBytes(job.id, 'occupancy.pgm');
      // The two files are replaced one after the other: a yaml that changed meanwhile may not
      // place this image (the next refresh reads both again).
      if (await fetchArtifactText(job.id, 'occupancy.yaml') !== text) return;
      const grid = parseOccupancy(bytes, text);
      const same = occupancyFiles && occupancyFiles.text === text && occupancyFiles.bytes.length === bytes.length &&
        occupancyFiles.bytes.every((v, i) => v === bytes[i]);
      if (stopped || !grid || same) return;
      occupancyFiles = { text, bytes };
      occupancy = grid;
      const occupied = grid.cells.reduce((n, v) => n + (v === 0 ? 1 : 0), 0);
      canvas.dataset.occupiedCells = String(occupied);
      const { occupancyKey } = await import('./viewer.js');
      if (stopped) return;
      clear(occupancyHolder, occupancyKey(grid, 'live-occupancy-key'));
      redraw();
    } catch (_) {
      // Not written yet (fewer than two keyframes fused) or being replaced: read it next time.
    }
  };
  const refresh = async () => {
    if (dense) refreshOccupancy();
    try {
      trajectoryJson = await fetchArtifactJson(job.id, 'trajectory.json');
      // Without events, the file's frames are the figures' only source.
      if (!source) for (const [i, f] of (trajectoryJson.frames || []).entries()) events.set(i, { ...f, frame_index: i });
      redraw();
      const bytes = await fetchArtifactBytes(job.id, 'map.ply');
      if (stopped || bytes.length === mapBytes) return;
      mapBytes = bytes.length;
      const cloud = parsePly(bytes.buffer);
      const { createScene } = await import('./viewer.js');
      if (stopped) return;
      if (scene) scene.dispose();
      clear(sceneHolder);
      mapNote.textContent = `${cloud.count.toLocaleString('en-US')} map points (map.ply as the server last wrote it).`;
      mapNote.dataset.points = String(cloud.count);
      scene = createScene(sceneHolder, { cloud, trajectory: liveTrajectory(trajectoryJson, [...events.values()]), title: 'map.ply' });
    } catch (_) {
      // Not written yet (no frame tracked) or being replaced: the next refresh reads it.
    }
  };
  refresh();
  const timer = setInterval(refresh, REFRESH_MS);
  return () => {
    stopped = true;
    clearInterval(timer);
    if (source) source.close();
    if (scene) scene.dispose();
  };
}
