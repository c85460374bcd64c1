// The pairs of a stereo_reconstruct job (api/stereo_json.h): for each pair its two images, the
// dense range panorama (range_png), how much of the mirror gave confident depth, the median
// range, the pair's warning in words, and one-click downloads of the range TIFF and the PLY.

import { artifactUrl, fetchArtifactBytes, imageUrl } from './api.js';
import { downloadList } from './artifacts.js';
import { colourKey, parseFloatTiff, rangeColourBar, rangePreviewScale } from './colorbar.js';
import { apiImage, clear, el, errorBox, formatNumber } from './ui.js';

// The pair's base name: pairs are matched by NAME in cam0/NAME and cam1/NAME.
const pairBase = (name) => name.replace(/^cam\d+\//, '');

// The pair's cloud: its own artifact, or the job's only cloud when there is one pair.
export function pairCloud(pair, result) {
  return pair.artifact || ((result.pairs || []).length === 1 ? result.artifact : null) || null;
}

// `onView(artifactName)` shows a cloud in the 3D viewer above (null: no button).
export function reconstructPairsCard(job, result, onView) {
  const pairs = result.pairs || [];
  if (!pairs.length) return null;
  const datasetId = job.dataset ?? job.dataset_id;
  const dense = result.method === 'dense' || pairs.some((p) => p.range_png);
  const scales = rangeScaleQueue(job.id);
  return el('div.card#reconstruct-pairs',
    el('h2', `${dense ? 'Dense' : 'Sparse'} reconstruction: ${pairs.length} pair${pairs.length === 1 ? '' : 's'}, ` +
      `${Number(result.num_points || 0).toLocaleString('en-US')} points`),
    result.warning ? el('div.warning#reconstruct-warning', result.warning) : null,
    pairs.length > 1 && result.clouds_merged === false
      ? el('p.muted', 'Each pair\'s cloud is in that pair\'s own cam0 frame, so the clouds are kept apart: choose one to view it.') : null,
    result.clouds_merged === true && result.trajectory
      ? el('p#reconstruct-merged', `${result.trajectory.num_pairs_placed} of ${pairs.length} pairs placed by ` +
        `${result.trajectory.source} and merged into cloud.ply, in that trajectory's world. `,
      onView ? el('button.view-cloud', { type: 'button', dataset: { artifact: 'cloud.ply' }, onclick: () => onView('cloud.ply') },
        'View the merged cloud') : null) : null,
    result.trajectory && result.trajectory.warning
      ? el('div.warning#reconstruct-trajectory-warning', result.trajectory.warning) : null,
    pairs.map((pair) => pairBlock(job, datasetId, pair, result, onView, scales)));
}

// The range panoramas' colour bars, one pair after the other: each needs the pair's float TIFF
// (the colours' scale is computed from the ranges, as the engine did when it drew the PNG).
function rangeScaleQueue(jobId) {
  let chain = Promise.resolve();
  return (holder, tiffName) => {
    chain = chain.then(async () => {
      try {
        const scale = rangePreviewScale(parseFloatTiff(await fetchArtifactBytes(jobId, tiffName)).data);
        clear(holder, scale ? rangeColourBar(scale) : colourKey({
          title: 'Range from cam0\'s centre',
          items: [{ colour: '#000', label: 'black: no cell of this panorama has a range' }],
        }));
      } catch (err) {
        clear(holder, errorBox(err, 'Could not read the range scale'));
      }
    });
  };
}

function pairBlock(job, datasetId, pair, result, onView, scales) {
  const base = pairBase(pair.name);
  const cloud = pairCloud(pair, result);
  const rows = [['Points', Number(pair.num_points || 0).toLocaleString('en-US')]];
  if (Number.isFinite(pair.confident_fraction)) {
    rows.push(['Confident depth', `${formatNumber(100 * pair.confident_fraction, 1)} % of the mirror cells` +
      (Number.isFinite(pair.num_mirror_cells) ? ` (${Number(pair.num_mirror_cells).toLocaleString('en-US')} cells)` : '')]);
  }
  if (Number.isFinite(pair.median_range_m)) {
    rows.push(['Median range', `${formatNumber(pair.median_range_m, 3)} m` +
      (Number.isFinite(pair.median_range_std_m) ? ` (median uncertainty ± ${formatNumber(pair.median_range_std_m, 3)} m)` : '')]);
  }
  if (Array.isArray(pair.num_keypoints)) rows.push(['Features (cam0 / cam1)', pair.num_keypoints.join(' / ')]);
  if (Number.isFinite(pair.num_matches)) rows.push(['Matches', String(pair.num_matches)]);
  const figure = (url, caption, attrs = {}, extra = null) => el('figure', attrs,
    el('a', { href: url, target: '_blank', title: 'full size' }, apiImage(url, { loading: 'lazy', alt: caption })),
    el('figcaption', caption), extra);
  let scaleHolder = null;
  if (pair.range_png && pair.range_tiff) {
    scaleHolder = el('div.range-scale', el('p.muted', 'Reading the range scale…'));
    scales(scaleHolder, pair.range_tiff);
  }
  return el('div.range-pair', { dataset: { pair: pair.name } },
    el('h3.mono', pair.name),
    pair.warning ? el('div.warning.pair-warning', pair.warning) : null,
    el('dl.kv', rows.map(([k, v]) => [el('dt', k), el('dd', v)])),
    el('div.overlays',
      figure(imageUrl(datasetId, `cam0/${base}`), `cam0/${base}`),
      figure(imageUrl(datasetId, `cam1/${base}`), `cam1/${base}`),
      pair.range_png ? figure(artifactUrl(job.id, pair.range_png),
        'Range panorama (from cam0\'s centre): columns are the azimuth over 360°, rows the angle from the baseline',
        { class: 'range-preview value-image' }, scaleHolder) : null),
    el('div.row',
      downloadList(job.id, [
        { name: pair.range_tiff, label: 'range TIFF (32-bit float metres)' },
        { name: cloud, label: 'point cloud PLY' }]),
      cloud && onView ? el('button.view-cloud', { type: 'button', dataset: { artifact: cloud }, onclick: () => onView(cloud) },
        'Show this pair in the 3D viewer') : null));
}
