// Trajectories in 2D: reading them (trajectory.json, TUM) and drawing a top view of the estimate
// against the ground truth, coloured by the SLAM state of each frame, with its loop closures.

// A trajectory is [{name, index, state, gap, t: [x, y, z], q: [w, x, y, z]}] with world_from_rig
// poses; index is the frame's position in the run and gap is true when frames without a pose
// (lost) come just before this one.
export function trajectoryFromJson(json) {
  const frames = Array.isArray(json) ? json : json.frames || json.trajectory || json.poses || [];
  const poses = [];
  let gap = false;
  frames.forEach((f, i) => {
    const pose = 'world_from_rig' in f ? f.world_from_rig : f.pose || f;
    const t = pose && (pose.translation_m || pose.t || [0, 0, 0]);
    if (!pose || !t.every(Number.isFinite)) {  // a frame that could not be tracked has no pose
      gap = true;
      return;
    }
    poses.push({ name: f.name ?? String(i), index: i, state: f.state, gap: gap && poses.length > 0, t, q: pose.rotation_wxyz || pose.q || [1, 0, 0, 0] });
    gap = false;
  });
  return poses;
}

// The colours of the top view: the estimate by state (older results without states draw as
// tracked), the ground truth, and the loop closures.
export const STATE_COLOURS = {
  tracked: '#2563eb',
  relocalised: '#9333ea',
  relinked: '#059669',
  reinitialised: '#dc2626',
};
export const GROUND_TRUTH_COLOUR = '#f59e0b';
export const LOOP_COLOUR = '#db2777';

export function stateColour(state) {
  return STATE_COLOURS[state] || STATE_COLOURS.tracked;  // "initialised" and unknown: tracked
}

// The two poses each loop of a result joins ([{frame, frame_index, matched_frame,
// matched_frame_index, ...}]), found by frame name, else by frame index; loops whose frames have
// no pose are left out. A result without loops (older ones) gives none.
export function loopSegments(estimate, loops) {
  if (!Array.isArray(loops)) return [];
  const byName = new Map(estimate.map((p) => [p.name, p]));
  const byIndex = new Map(estimate.filter((p) => Number.isInteger(p.index)).map((p) => [p.index, p]));
  const find = (name, index) => byName.get(name) || byIndex.get(index);
  return loops.map((loop) => [find(loop.frame, loop.frame_index), find(loop.matched_frame, loop.matched_frame_index)])
    .filter(([a, b]) => a && b);
}

// Quaternion helpers for world_from_rig poses {t, q (w, x, y, z)}.
function rotate([w, x, y, z], [px, py, pz]) {
  // v' = v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z)
  const cx = y * pz - z * py;
  const cy = z * px - x * pz;
  const cz = x * py - y * px;
  return [px + 2 * (w * cx + y * cz - z * cy), py + 2 * (w * cy + z * cx - x * cz), pz + 2 * (w * cz + x * cy - y * cx)];
}

function multiply([aw, ax, ay, az], [bw, bx, by, bz]) {
  return [aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
    aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw];
}

// The inverse of a {rotation_wxyz, translation_m} pose, as the same kind of object.
export function inversePose(pose) {
  const [w, x, y, z] = pose.rotation_wxyz;
  const q = [w, -x, -y, -z];
  const t = rotate(q, pose.translation_m).map((v) => -v);
  return { rotation_wxyz: q, translation_m: t };
}

// Applies a_from_b (a {rotation_wxyz, translation_m} pose) to a trajectory given in frame b.
export function transformTrajectory(poses, aFromB) {
  const q = aFromB.rotation_wxyz;
  const t = aFromB.translation_m;
  return poses.map((p) => ({ ...p, t: rotate(q, p.t).map((v, k) => v + t[k]), q: multiply(q, p.q) }));
}

// TUM: "timestamp tx ty tz qx qy qz qw" per line; '#' starts a comment.
export function parseTum(text) {
  return text.split('\n').map((l) => l.trim()).filter((l) => l && !l.startsWith('#')).map((line) => {
    const [time, tx, ty, tz, qx, qy, qz, qw] = line.split(/\s+/).map(Number);
    return { name: String(time), t: [tx, ty, tz], q: [qw, qx, qy, qz] };
  }).filter((p) => p.t.every(Number.isFinite));
}

// A binary PGM (P5, 8-bit): {cols, rows, cells}.
export function parsePgm(bytes) {
  let at = 0;
  const token = () => {
    for (;;) {
      while (at < bytes.length && /\s/.test(String.fromCharCode(bytes[at]))) at += 1;
      if (bytes[at] !== 35) break;  // '#': a comment to the end of the line
      while (at < bytes.length && bytes[at] !== 10) at += 1;
    }
    let text = '';
    while (at < bytes.length && !/\s/.test(String.fromCharCode(bytes[at]))) text += String.fromCharCode(bytes[at++]);
    return text;
  };
  if (token() !== 'P5') throw new Error('not a binary PGM');
  const cols = Number(token());
  const rows = Number(token());
  if (Number(token()) > 255) throw new Error('a 16-bit PGM');
  at += 1;  // the single whitespace after the header
  return { cols, rows, cells: bytes.subarray(at, at + cols * rows) };
}

// The occupancy grid's colours on the top view, as map_server's viewers show them.
export const OCCUPANCY_COLOURS = { occupied: [17, 24, 39], free: [255, 255, 255], unknown: [203, 213, 225] };

// A slam job's occupancy grid from its ROS map_server files (occupancy.pgm's bytes and
// occupancy.yaml's text): {cols, rows, cells (0 occupied, 254 free, 205 unknown; row 0 the
// largest y), cell_m, origin_m: [x, y] of the lower-left corner}, or null when the yaml lacks
// the resolution or origin. Throws when the PGM is not a binary 8-bit one.
export function parseOccupancy(bytes, yamlText) {
  const grid = parsePgm(bytes);
  const resolution = /resolution:\s*([-\d.eE+]+)/.exec(yamlText);
  const origin = /origin:\s*\[\s*([-\d.eE+]+)\s*,\s*([-\d.eE+]+)/.exec(yamlText);
  if (!resolution || !origin) return null;
  return { ...grid, cell_m: Number(resolution[1]), origin_m: [Number(origin[1]), Number(origin[2])] };
}

// The two axes along which the trajectories spread most: the "ground plane" whatever the
// convention (y down for camera frames, z up for a robot).
function planeAxes(poses) {
  const spread = [0, 1, 2].map((k) => {
    const values = poses.map((p) => p.t[k]);
    return Math.max(...values) - Math.min(...values);
  });
  return [0, 1, 2].sort((a, b) => spread[b] - spread[a]).slice(0, 2).sort((a, b) => a - b);
}

// `occupancy` (optional): the dense map's grid in the world's x-y plane ({cols, rows, cells,
// cell_m, origin_m}, ROS map_server conventions), drawn under the trajectories in `colours`
// ({occupied, free, unknown}: [r, g, b]); the view is then the x-y plane whatever the spread.
export function drawTopView(canvas, estimate, groundTruth, loops = [], occupancy = null, colours = null) {
  const ctx = canvas.getContext('2d');
  const w = canvas.width;
  const h = canvas.height;
  ctx.clearRect(0, 0, w, h);
  const all = [...estimate, ...(groundTruth || [])];
  if (!all.length) return;
  const [a, b] = occupancy ? [0, 1] : planeAxes(all);
  const us = all.map((p) => p.t[a]);
  const vs = all.map((p) => p.t[b]);
  if (occupancy) {
    const [ox, oy] = occupancy.origin_m;
    us.push(ox, ox + occupancy.cols * occupancy.cell_m);
    vs.push(oy, oy + occupancy.rows * occupancy.cell_m);
  }
  const [uMin, uMax, vMin, vMax] = [Math.min(...us), Math.max(...us), Math.min(...vs), Math.max(...vs)];
  const span = Math.max(uMax - uMin, vMax - vMin, 1e-6);
  const scale = (Math.min(w, h) - 60) / span;
  const toCanvas = (p) => [w / 2 + (p.t[a] - (uMin + uMax) / 2) * scale, h / 2 - (p.t[b] - (vMin + vMax) / 2) * scale];
  if (occupancy) drawOccupancy(ctx, occupancy, colours, toCanvas, scale);
  drawScaleBar(ctx, w, h, scale, 'xyz'[a], 'xyz'[b]);
  const line = (poses, color, width) => {
    ctx.strokeStyle = color;
    ctx.lineWidth = width;
    ctx.beginPath();
    poses.forEach((p, i) => {
      const [x, y] = toCanvas(p);
      if (i) ctx.lineTo(x, y);
      else ctx.moveTo(x, y);
    });
    ctx.stroke();
    if (poses.length) {
      const [x, y] = toCanvas(poses[0]);
      ctx.fillStyle = color;
      ctx.fillRect(x - 3, y - 3, 6, 6);
    }
  };
  if (groundTruth && groundTruth.length) line(groundTruth, GROUND_TRUTH_COLOUR, 3);
  drawEstimate(ctx, estimate, toCanvas);
  ctx.strokeStyle = LOOP_COLOUR;
  ctx.lineWidth = 2;
  for (const [a, b] of loopSegments(estimate, loops)) {
    const [ax, ay] = toCanvas(a);
    const [bx, by] = toCanvas(b);
    ctx.beginPath();
    ctx.moveTo(ax, ay);
    ctx.lineTo(bx, by);
    ctx.stroke();
    ctx.fillStyle = LOOP_COLOUR;
    for (const [x, y] of [[ax, ay], [bx, by]]) {
      ctx.beginPath();
      ctx.arc(x, y, 3.5, 0, 2 * Math.PI);
      ctx.fill();
    }
  }
}

// The grid as an image under everything else: its upper-left corner is (origin x, origin y +
// rows x cell), row 0 being the largest y.
function drawOccupancy(ctx, grid, colours, toCanvas, scale) {
  const image = new ImageData(grid.cols, grid.rows);
  for (let i = 0; i < grid.cols * grid.rows; i += 1) {
    const v = grid.cells[i];
    const [r, g, b] = v === 0 ? colours.occupied : v === 254 ? colours.free : colours.unknown;
    image.data.set([r, g, b, 255], 4 * i);
  }
  const bitmap = document.createElement('canvas');
  bitmap.width = grid.cols;
  bitmap.height = grid.rows;
  bitmap.getContext('2d').putImageData(image, 0, 0);
  const [ox, oy] = grid.origin_m;
  const [x, y] = toCanvas({ t: [ox, oy + grid.rows * grid.cell_m, 0] });
  ctx.save();
  ctx.imageSmoothingEnabled = false;
  ctx.drawImage(bitmap, x, y, grid.cols * grid.cell_m * scale, grid.rows * grid.cell_m * scale);
  ctx.restore();
}

// The estimate segment by segment, each in the colour of the state of the frame it leads to;
// no segment across frames without a pose.
function drawEstimate(ctx, estimate, toCanvas) {
  ctx.lineWidth = 2;
  for (let i = 1; i < estimate.length; i += 1) {
    if (estimate[i].gap) continue;
    const [x0, y0] = toCanvas(estimate[i - 1]);
    const [x1, y1] = toCanvas(estimate[i]);
    ctx.strokeStyle = stateColour(estimate[i].state);
    ctx.beginPath();
    ctx.moveTo(x0, y0);
    ctx.lineTo(x1, y1);
    ctx.stroke();
  }
  if (estimate.length) {
    const [x, y] = toCanvas(estimate[0]);
    ctx.fillStyle = stateColour(estimate[0].state);
    ctx.fillRect(x - 3, y - 3, 6, 6);
  }
}

function drawScaleBar(ctx, w, h, scale, axisU, axisV) {
  const metres = 10 ** Math.floor(Math.log10(Math.max(1e-6, (w * 0.25) / scale)));
  const length = metres * scale;
  ctx.strokeStyle = '#111';
  ctx.fillStyle = '#111';
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(20, h - 20);
  ctx.lineTo(20 + length, h - 20);
  ctx.stroke();
  ctx.font = '12px system-ui, sans-serif';
  ctx.fillText(`${metres >= 1 ? metres : metres.toPrecision(1)} m`, 20, h - 28);
  ctx.fillText(`horizontal: ${axisU}, vertical: ${axisV}`, w - 160, h - 14);
}
