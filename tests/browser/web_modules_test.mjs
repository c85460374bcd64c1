// Unit tests of the web page's pure modules (no browser): the PLY reader, the trajectory
// helpers, the colour bars' readers and scales, the result keys in words, the cloud colouring. Run by ctest as browser/web_modules: node web_modules_test.mjs
import assert from 'node:assert/strict';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const WEB_JS = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../../web/js');
const { parsePly } = await import(path.join(WEB_JS, 'ply.js'));
const { inversePose, loopSegments, parseOccupancy, parsePgm, parseTum, stateColour, STATE_COLOURS, trajectoryFromJson, transformTrajectory } =
  await import(path.join(WEB_JS, 'topview.js'));
const { JET, parseFloatTiff, rangePreviewScale, ticks, TURBO } = await import(path.join(WEB_JS, 'colorbar.js'));
const { describeKey, formatLength, formatWithUnit, shortId } = await import(path.join(WEB_JS, 'labels.js'));
const { colourModes, percentileRange, pointValues, turboColours } = await import(path.join(WEB_JS, 'cloud_colour.js'));
const { liveFigures, liveTrajectory, percentile } = await import(path.join(WEB_JS, 'live_report.js'));

// A TIFF laid out as OpenCV writes a CV_32FC1 image: little-endian, uncompressed, the pixels in
// strips of `rowsPerStrip` rows, strip offsets (LONG) and byte counts (SHORT) in arrays.
function floatTiff(width, height, values, rowsPerStrip) {
  const strips = Math.ceil(height / rowsPerStrip);
  const tags = [[256, 3, 1, width], [257, 3, 1, height], [258, 3, 1, 32], [259, 3, 1, 1], [262, 3, 1, 1],
    [273, 4, strips, null], [277, 3, 1, 1], [278, 3, 1, rowsPerStrip], [279, 3, strips, null], [339, 3, 1, 3]];
  const dataAt = 8;
  const ifdAt = dataAt + 4 * values.length;
  const arraysAt = ifdAt + 2 + 12 * tags.length + 4;
  const bytes = new Uint8Array(arraysAt + 6 * strips);
  const view = new DataView(bytes.buffer);
  bytes.set([0x49, 0x49, 42, 0]);
  view.setUint32(4, ifdAt, true);
  values.forEach((v, i) => view.setFloat32(dataAt + 4 * i, v, true));
  view.setUint16(ifdAt, tags.length, true);
  tags.forEach(([tag, type, count, value], i) => {
    const at = ifdAt + 2 + 12 * i;
    view.setUint16(at, tag, true);
    view.setUint16(at + 2, type, true);
    view.setUint32(at + 4, count, true);
    if (tag === 273) view.setUint32(at + 8, arraysAt, true);
    else if (tag === 279) view.setUint32(at + 8, arraysAt + 4 * strips, true);
    else view.setUint16(at + 8, value, true);
  });
  for (let s = 0; s < strips; s += 1) {
    const rows = Math.min(rowsPerStrip, height - s * rowsPerStrip);
    view.setUint32(arraysAt + 4 * s, dataAt + 4 * width * rowsPerStrip * s, true);
    view.setUint16(arraysAt + 4 * strips + 2 * s, 4 * width * rows, true);
  }
  return bytes;
}

// A binary little-endian PLY as omnirig's SLAM writes it, preceded by an element the reader skips.
function binaryPly(points) {
  const header = 'ply\nformat binary_little_endian 1.0\nelement camera 1\nproperty double t\n' +
    `element vertex ${points.length}\nproperty float x\nproperty float y\nproperty float z\n` +
    'property uchar red\nproperty uchar green\nproperty uchar blue\nproperty int num_observations\nend_header\n';
  const head = new TextEncoder().encode(header);
  const bytes = new Uint8Array(head.length + 8 + points.length * 19);
  bytes.set(head);
  const view = new DataView(bytes.buffer);
  view.setFloat64(head.length, 42, true);
  points.forEach(([x, y, z, r, g, b, n], i) => {
    const o = head.length + 8 + i * 19;
    view.setFloat32(o, x, true);
    view.setFloat32(o + 4, y, true);
    view.setFloat32(o + 8, z, true);
    bytes.set([r, g, b], o + 12);
    view.setInt32(o + 15, n, true);
  });
  return bytes;
}

const tests = {
  'float TIFF in strips, as OpenCV writes range panoramas'() {
    const values = Array.from({ length: 5 * 7 }, (_, i) => i * 0.5);
    const tiff = parseFloatTiff(floatTiff(5, 7, values, 3));
    assert.equal(tiff.width, 5);
    assert.equal(tiff.height, 7);
    assert.deepEqual([...tiff.data], values);
    const compressed = floatTiff(1, 1, [1], 1);
    new DataView(compressed.buffer).setUint16(8 + 4 + 2 + 12 * 3 + 8, 5, true);  // LZW
    assert.throws(() => parseFloatTiff(compressed), /compressed/);
  },
  'range scale: 2nd and 98th percentiles of every 8th known cell, as the engine draws them'() {
    // 0 is unknown; the known cells are 1..1000 m, every 8th of them kept: 1, 9, 17, ...
    const ranges = [];
    for (let r = 1; r <= 1000; r += 1) ranges.push(0, r);
    const scale = rangePreviewScale(Float32Array.from(ranges));
    const kept = Array.from({ length: 125 }, (_, i) => 1 + 8 * i);
    assert.equal(scale.near_m.toFixed(6), kept[Math.floor(0.02 * 124)].toFixed(6));
    assert.equal(scale.far_m.toFixed(6), kept[Math.floor(0.98 * 124)].toFixed(6));
    assert.equal(rangePreviewScale(new Float32Array(4)), null);
  },
  'colour maps are OpenCV\'s: 256 entries, TURBO from dark blue to dark red, JET from blue to red'() {
    assert.equal(TURBO.length, 256);
    assert.deepEqual(TURBO[0], [0x30, 0x12, 0x3b]);
    assert.deepEqual(JET[0], [0, 0, 128]);
    assert.deepEqual(JET[255], [128, 0, 0]);
  },
  'ticks: round values inside the range, logarithmic at 1, 2, 5 x 10^k'() {
    assert.deepEqual(ticks(0.8, 30, true), [1, 2, 5, 10, 20]);
    assert.deepEqual(ticks(0, 0.5, false), [0, 0.1, 0.2, 0.3, 0.4, 0.5]);
  },
  'binary PGM of an occupancy grid, with a comment'() {
    const bytes = new Uint8Array([...new TextEncoder().encode('P5\n# map\n3 2\n255\n'), 0, 254, 205, 205, 0, 254]);
    const grid = parsePgm(bytes);
    assert.equal(grid.cols, 3);
    assert.equal(grid.rows, 2);
    assert.deepEqual([...grid.cells], [0, 254, 205, 205, 0, 254]);
  },
  'occupancy grid from its map_server files: the PGM placed by the yaml'() {
    const bytes = new Uint8Array([...new TextEncoder().encode('P5\n2 1\n255\n'), 0, 254]);
    const yaml = 'image: occupancy.pgm\nresolution: 0.05\norigin: [-1.25, 0.5e-1, 0.0]\nnegate: 0\n';
    const grid = parseOccupancy(bytes, yaml);
    assert.equal(grid.cols, 2);
    assert.equal(grid.cell_m, 0.05);
    assert.deepEqual(grid.origin_m, [-1.25, 0.05]);
    assert.deepEqual([...grid.cells], [0, 254]);
    assert.equal(parseOccupancy(bytes, 'image: occupancy.pgm\n'), null);  // no resolution nor origin
    assert.throws(() => parseOccupancy(new TextEncoder().encode('P2\n1 1\n255\n0'), yaml));
  },
  'result keys in words with their units'() {
    assert.deepEqual(describeKey('num_scale_inliers'), { label: 'scale inliers', unit: '' });
    assert.deepEqual(describeKey('median_range_std_m'), { label: 'median range std', unit: 'm' });
    assert.deepEqual(describeKey('ate_rmse_m'), { label: 'ATE (RMSE)', unit: 'm' });
    assert.equal(formatWithUnit('frames_per_second', 8.5), '8.5000 frames/s');
    assert.equal(formatWithUnit('final_drift_percent', 1.5), '1.5000 %');
    assert.equal(formatWithUnit('rotation_std_deg', 2), '2°');
    assert.equal(formatWithUnit('num_keyframes', 12), '12');
    assert.equal(shortId('f4ba8870de2b7a2e'), 'f4ba8870');
  },
  'binary PLY: positions, colours and extra properties'() {
    const cloud = parsePly(binaryPly([[1, 2, 3, 10, 20, 30, 4], [-1.5, 0.25, 7, 255, 0, 1, 9]]));
    assert.equal(cloud.count, 2);
    assert.deepEqual([...cloud.positions], [1, 2, 3, -1.5, 0.25, 7]);
    assert.deepEqual([...cloud.colors], [10, 20, 30, 255, 0, 1]);
    assert.deepEqual([...cloud.extra.num_observations], [4, 9]);
  },
  'ASCII PLY without colours'() {
    const text = 'ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 5 6\n';
    const cloud = parsePly(new TextEncoder().encode(text));
    assert.deepEqual([...cloud.positions], [1, 2, 3, 4, 5, 6]);
    assert.equal(cloud.colors, null);
  },
  'bad PLY files are refused with a message'() {
    const full = binaryPly([[1, 2, 3, 1, 2, 3, 1]]);
    assert.throws(() => parsePly(full.subarray(0, full.length - 5)), /truncated/);
    assert.throws(() => parsePly(new TextEncoder().encode('hello')), /not a PLY/);
    const bigEndian = new TextDecoder().decode(full).replace('binary_little_endian', 'binary_big_endian');
    assert.throws(() => parsePly(new TextEncoder().encode(bigEndian)), /not supported/);
  },
  'trajectory.json frames without a pose are left out'() {
    const poses = trajectoryFromJson({ frames: [{ name: 'a', state: 'lost', world_from_rig: null },
      { name: 'b', state: 'tracked', world_from_rig: { rotation_wxyz: [1, 0, 0, 0], translation_m: [1, 2, 3] } }] });
    assert.deepEqual(poses.map((p) => p.name), ['b']);
    assert.deepEqual(poses[0].t, [1, 2, 3]);
  },
  'lost frames leave a gap before the next pose, states are kept'() {
    const at = (x) => ({ rotation_wxyz: [1, 0, 0, 0], translation_m: [x, 0, 0] });
    const poses = trajectoryFromJson({ frames: [
      { name: 'f0', state: 'initialised', world_from_rig: at(0) }, { name: 'f1', state: 'tracked', world_from_rig: at(1) },
      { name: 'f2', state: 'lost', world_from_rig: null }, { name: 'f3', state: 'reinitialised', world_from_rig: at(3) },
      { name: 'f4', state: 'relinked', world_from_rig: at(4) }] });
    assert.deepEqual(poses.map((p) => [p.name, p.index, p.gap]), [['f0', 0, false], ['f1', 1, false], ['f3', 3, true], ['f4', 4, false]]);
    assert.equal(stateColour(poses[3].state), STATE_COLOURS.relinked);
    assert.equal(stateColour('initialised'), STATE_COLOURS.tracked);
    assert.equal(stateColour(undefined), STATE_COLOURS.tracked);  // results from before states
  },
  'loops join their frames by name, else by index; missing ones are left out'() {
    const poses = trajectoryFromJson([0, 1, 2].map((i) => ({ name: `f${i}`, world_from_rig: { rotation_wxyz: [1, 0, 0, 0], translation_m: [i, 0, 0] } })));
    const segments = loopSegments(poses, [
      { frame: 'f2', frame_index: 2, matched_frame: 'f0', matched_frame_index: 0 },
      { frame: 'renamed', frame_index: 1, matched_frame: 'f0', matched_frame_index: 0 },
      { frame: 'f9', frame_index: 9, matched_frame: 'f0', matched_frame_index: 0 }]);
    assert.deepEqual(segments.map(([a, b]) => [a.name, b.name]), [['f2', 'f0'], ['f1', 'f0']]);
    assert.deepEqual(loopSegments(poses, undefined), []);  // results from before loops
  },
  'TUM lines become poses with (w, x, y, z) quaternions'() {
    const poses = parseTum('# t tx ty tz qx qy qz qw\n0.5 1 2 3 0 0 0.6 0.8\n\n');
    assert.equal(poses.length, 1);
    assert.deepEqual(poses[0].t, [1, 2, 3]);
    assert.deepEqual(poses[0].q, [0.8, 0, 0, 0.6]);
  },
  'a pose and its inverse cancel, and rotate points the right way'() {
    const half = Math.SQRT1_2;
    const aFromB = { rotation_wxyz: [half, 0, 0, half], translation_m: [1, 2, 3] };  // 90 deg about z
    const [moved] = transformTrajectory([{ t: [1, 0, 0], q: [1, 0, 0, 0] }], aFromB);
    moved.t.forEach((v, k) => assert.ok(Math.abs(v - [1, 3, 3][k]) < 1e-12, `moved ${moved.t}`));
    const [back] = transformTrajectory([moved], inversePose(aFromB));
    back.t.forEach((v, k) => assert.ok(Math.abs(v - [1, 0, 0][k]) < 1e-12, `back ${back.t}`));
    assert.ok(Math.abs(Math.abs(back.q[0]) - 1) < 1e-12);
  },
  'a cloud is coloured by height along the up axis, range from the origin, or confidence'() {
    const cloud = { count: 3, positions: Float32Array.from([0, -2, 0, 3, 0, 4, 0, 1, 0]), colors: null,
      extra: { confidence: Float32Array.from([0.1, 0.5, 0.9]) } };
    assert.deepEqual(colourModes(cloud).map((m) => m.mode), ['height', 'range', 'confidence']);
    assert.deepEqual(colourModes({ ...cloud, colors: new Uint8Array(9), extra: {} }).map((m) => m.mode), ['rgb', 'height', 'range']);
    assert.deepEqual([...pointValues(cloud, 'height', [0, -1, 0])].map((v) => v + 0), [2, 0, -1]);
    assert.deepEqual([...pointValues(cloud, 'range')], [2, 5, 1]);
    assert.equal(pointValues(cloud, 'confidence'), cloud.extra.confidence);
    const colours = turboColours(Float32Array.from([-1, 0, 1, 2, NaN]), [0, 1]);
    assert.deepEqual([...colours.subarray(0, 3)], TURBO[0]);  // clamped below
    assert.deepEqual([...colours.subarray(6, 9)], TURBO[255]);
    assert.deepEqual([...colours.subarray(9, 12)], TURBO[255]);  // clamped above
    assert.deepEqual([...colours.subarray(12, 15)], TURBO[0]);  // no value
  },
  'the colour range leaves out the 2 % at either end'() {
    const values = Float32Array.from({ length: 1001 }, (_, i) => i);
    values[1000] = 1e9;  // a stray point far away
    assert.deepEqual(percentileRange(values), [20, 980]);
    const [lo, hi] = percentileRange(Float32Array.from([3, 3, 3]));
    assert.ok(lo === 3 && hi > lo);
  },
  'a live run\'s figures: frames received, tracked, skipped, rate over capture time, latency'() {
    const pose = (x) => ({ translation_m: [x, 0, 0], rotation_wxyz: [1, 0, 0, 0] });
    // 21 frames at 20 Hz of capture time, frame 5 lost, 3 skipped by the server so far.
    const events = Array.from({ length: 21 }, (_, i) => ({
      frame_index: i, name: `t${i}`, stamp_s: 100 + i * 0.05, state: i === 5 ? 'lost' : 'tracked',
      keyframe: i % 4 === 0, in_map: i >= 10, world_from_rig: i === 5 ? null : pose(i), latency_ms: i + 1,
      num_skipped: Math.min(i, 3) })).reverse();
    const figures = liveFigures(events);
    assert.equal(figures.received, 24);
    assert.equal(figures.tracked, 20);
    assert.equal(figures.lost, 1);
    assert.equal(figures.skipped, 3);
    assert.equal(figures.keyframes, 6);
    assert.equal(figures.inMap, 11);
    assert.ok(Math.abs(figures.rateHz - 20) < 1e-9);
    assert.equal(figures.latencyP50Ms, 11);
    assert.equal(figures.latencyP95Ms, 20);
    assert.ok(Number.isNaN(liveFigures([]).rateHz));
    assert.equal(percentile([5, 1, 3], 100), 5);
    // The file's poses, then the frames that arrived after it was written.
    const file = { frames: [{ name: 't0', world_from_rig: pose(0.5) }, { name: 't1', world_from_rig: null }] };
    const drawn = liveTrajectory(file, events.slice(-3));
    assert.deepEqual(drawn.map((p) => p.t[0]), [0.5, 2]);
    assert.equal(drawn[1].index, 2);
  },
  'lengths in m, cm or mm by size'() {
    assert.equal(formatLength(1.234), '1.23 m');
    assert.equal(formatLength(0.0456), '4.56 cm');
    assert.equal(formatLength(0.0012), '1.2 mm');
    assert.equal(formatLength(NaN), '–');
  },
};

let failed = 0;
for (const [name, test] of Object.entries(tests)) {
  try {
    test();
    console.log(`ok   ${name}`);
  } catch (e) {
    failed += 1;
    console.log(`FAIL ${name}\n${e.stack}`);
  }
}
process.exit(failed ? 1 : 0);
