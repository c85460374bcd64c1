// Colouring a point cloud by a value, as Potree does: height along the up axis, range from the
// cloud's origin (cam0's centre for a stereo pair, the first frame for a SLAM map), or the dense
// stereo confidence when the PLY carries it; TURBO between the 2nd and 98th percentiles.

import { TURBO } from './colorbar.js';

// The modes a cloud offers: [{mode, label, unit}]; 'rgb' when it has colours.
export function colourModes(cloud) {
  const modes = [];
  if (cloud.colors) modes.push({ mode: 'rgb', label: 'its colours', unit: '' });
  modes.push({ mode: 'height', label: 'height', unit: 'm' }, { mode: 'range', label: 'range from the origin', unit: 'm' });
  if (cloud.extra && cloud.extra.confidence) modes.push({ mode: 'confidence', label: 'confidence', unit: '0 to 1' });
  return modes;
}

// The value of each point for `mode` ('height' along `up`, a unit vector [x, y, z]).
export function pointValues(cloud, mode, up = [0, -1, 0]) {
  if (mode === 'confidence') return cloud.extra.confidence;
  const p = cloud.positions;
  const out = new Float32Array(cloud.count);
  for (let i = 0; i < cloud.count; i += 1) {
    const x = p[3 * i];
    const y = p[3 * i + 1];
    const z = p[3 * i + 2];
    out[i] = mode === 'range' ? Math.hypot(x, y, z) : x * up[0] + y * up[1] + z * up[2];
  }
  return out;
}

// The 2nd and 98th percentiles of the finite values (of at most ~20,000 of them): [min, max],
// max > min.
export function percentileRange(values) {
  const step = Math.max(1, Math.floor(values.length / 20000));
  const sample = [];
  for (let i = 0; i < values.length; i += step) if (Number.isFinite(values[i])) sample.push(values[i]);
  if (!sample.length) return [0, 1];
  sample.sort((a, b) => a - b);
  const lo = sample[Math.floor(0.02 * (sample.length - 1))];
  const hi = sample[Math.ceil(0.98 * (sample.length - 1))];
  return hi > lo ? [lo, hi] : [lo, lo + 1e-6];
}

// TURBO colours (RGB bytes) of the values over [min, max], clamped.
export function turboColours(values, [min, max]) {
  const out = new Uint8Array(3 * values.length);
  const scale = 255 / (max - min);
  for (let i = 0; i < values.length; i += 1) {
    const v = values[i];
    const k = Number.isFinite(v) ? Math.max(0, Math.min(255, Math.round((v - min) * scale))) : 0;
    const c = TURBO[k];
    out[3 * i] = c[0];
    out[3 * i + 1] = c[1];
    out[3 * i + 2] = c[2];
  }
  return out;
}
