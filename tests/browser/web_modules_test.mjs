// Unit tests of the web page's pure modules (no browser): the PLY reader and the trajectory
// helpers. Run by ctest as browser/web_modules: node web_modules_test.mjs
import assert from 'node:assert/strict';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const WEB_JS = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../../web/js');
const { parsePly } = await import(path.join(WEB_JS, 'ply.js'));
const { inversePose, loopSegments, parseTum, stateColour, STATE_COLOURS, trajectoryFromJson, transformTrajectory } =
  await import(path.join(WEB_JS, 'topview.js'));

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
