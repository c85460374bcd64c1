// Result keys as people read them: "num_scale_inliers" -> "scale inliers", "ate_rmse_m" ->
// "ATE (RMSE)" in m, and every number with its unit. The unit comes from the key's suffix, the
// naming rule of the results (_m, _mm, _px, _deg, _rad, _s, _percent); a few keys are named
// outright where the rule alone reads badly.

import { formatNumber } from './ui.js';

const UNIT_SUFFIXES = [
  ['_percent', '%'], ['_mm', 'mm'], ['_px', 'px'], ['_deg', '°'], ['_rad', 'rad'], ['_m', 'm'],
  ['_seconds', 's'], ['_s', 's'], ['_bytes', 'bytes'],
];

const NAMED = {
  ate_rmse_m: 'ATE (RMSE)',
  ate_max_m: 'ATE (max)',
  rpe_translation_rmse_m: 'RPE translation (RMSE)',
  rpe_rotation_rmse_deg: 'RPE rotation (RMSE)',
  frames_per_second: ['frame rate', 'frames/s'],
  num_frames: 'frames',
  num_tracked: 'frames tracked',
  num_lost: 'frames lost',
  num_keyframes: 'keyframes',
  num_map_points: 'map points',
  rms_px: 'RMS reprojection error',
  times_s: 'stage times',
  timestamp_s: 'timestamp',
  final_drift_percent: 'final drift',
  max_drift_percent: 'largest drift',
  path_length_m: 'path length',
  num_features: 'features (cam0 / cam1)',
  motion_source: 'motion from',
};

// {label, unit} of a result key ('' when it has no unit).
export function describeKey(key) {
  const named = NAMED[key];
  if (Array.isArray(named)) return { label: named[0], unit: named[1] };
  let unit = '';
  let base = key;
  for (const [suffix, name] of UNIT_SUFFIXES) {
    if (key.endsWith(suffix) && key.length > suffix.length) {
      unit = name;
      base = key.slice(0, -suffix.length);
      break;
    }
  }
  if (named) return { label: named, unit };
  const words = base.replace(/^num_/, '').replace(/_/g, ' ').trim();
  return { label: words, unit };
}

export const labelOf = (key) => describeKey(key).label;

// A number with the unit its key names: "0.0123 m", "8.47 frames/s", "42 %".
export function formatWithUnit(key, value, digits = 4) {
  const { unit } = describeKey(key);
  const number = typeof value === 'number' && !Number.isInteger(value) ? formatNumber(value, digits) : String(value);
  if (!unit || typeof value !== 'number') return number;
  return unit === '%' || unit === '°' ? `${number}${unit === '%' ? ' %' : '°'}` : `${number} ${unit}`;
}

// Short, readable ids: the first 8 of the 16 hex digits (unique enough to tell jobs apart on a page).
export const shortId = (id) => String(id ?? '').slice(0, 8);

// Lengths as people read them: metres, centimetres or millimetres by size.
export function formatLength(metres) {
  if (!Number.isFinite(metres)) return '–';
  const a = Math.abs(metres);
  if (a >= 1) return `${formatNumber(metres, 2)} m`;
  if (a >= 0.01) return `${Number((metres * 100).toPrecision(3))} cm`;
  return `${Number((metres * 1000).toPrecision(2))} mm`;
}
