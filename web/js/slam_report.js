// The slam report's error figures as evo plots them: the translation and rotation error of each
// frame against the distance travelled (the result's evaluation.per_frame, after the alignment),
// and the relative pose error per 1 m / 10 m of path (evaluation.rpe_segments). Plain canvas.

import { formatLength } from './labels.js';
import { el, formatNumber } from './ui.js';

// Round steps (1, 2, 5 x 10^k) from 0 to at least `max`.
function axisTicks(max, count = 4) {
  if (!(max > 0)) return [0, 1];
  const raw = max / count;
  const power = 10 ** Math.floor(Math.log10(raw));
  const step = [1, 2, 5, 10].map((m) => m * power).find((s) => s >= raw) || raw;
  const out = [];
  for (let v = 0; v < max + step * 0.999; v += step) out.push(Number(v.toPrecision(12)));
  return out;
}

const tickText = (v) => String(Number(v.toPrecision(3)));

// A line plot of ys against xs on `canvas`, axes from 0, ticks and axis titles with their units;
// `scale` turns the values into the unit shown (e.g. m -> cm). The canvas keeps what it shows in
// data attributes (points, x and y units, the largest value) for tests and readers of the page.
export function drawLinePlot(canvas, xs, ys, { xTitle, yTitle, colour = '#2563eb', scale = 1 }) {
  const ratio = window.devicePixelRatio || 1;
  const width = canvas.clientWidth || canvas.width;
  const height = canvas.clientHeight || canvas.height;
  canvas.width = Math.round(width * ratio);
  canvas.height = Math.round(height * ratio);
  const ctx = canvas.getContext('2d');
  ctx.scale(ratio, ratio);
  ctx.clearRect(0, 0, width, height);
  const left = 56;
  const bottom = 40;
  const top = 12;
  const right = 12;
  const plotW = width - left - right;
  const plotH = height - top - bottom;
  const values = ys.map((y) => y * scale);
  const xTicks = axisTicks(Math.max(...xs, 0));
  const yTicks = axisTicks(Math.max(...values.filter(Number.isFinite), 0));
  const xMax = xTicks[xTicks.length - 1];
  const yMax = yTicks[yTicks.length - 1];
  const px = (x) => left + (plotW * x) / xMax;
  const py = (y) => top + plotH * (1 - y / yMax);
  ctx.font = '11px system-ui, sans-serif';
  ctx.strokeStyle = '#dde1e6';
  ctx.fillStyle = '#69727d';
  ctx.lineWidth = 1;
  ctx.textAlign = 'right';
  ctx.textBaseline = 'middle';
  for (const t of yTicks) {
    ctx.beginPath();
    ctx.moveTo(left, py(t));
    ctx.lineTo(left + plotW, py(t));
    ctx.stroke();
    ctx.fillText(tickText(t), left - 6, py(t));
  }
  ctx.textAlign = 'center';
  ctx.textBaseline = 'top';
  for (const t of xTicks) {
    ctx.beginPath();
    ctx.moveTo(px(t), top);
    ctx.lineTo(px(t), top + plotH);
    ctx.stroke();
    ctx.fillText(tickText(t), px(t), top + plotH + 5);
  }
  ctx.fillText(xTitle, left + plotW / 2, top + plotH + 22);
  ctx.save();
  ctx.translate(12, top + plotH / 2);
  ctx.rotate(-Math.PI / 2);
  ctx.textBaseline = 'middle';
  ctx.fillText(yTitle, 0, 0);
  ctx.restore();
  ctx.strokeStyle = colour;
  ctx.fillStyle = colour;
  ctx.lineWidth = 2;
  ctx.beginPath();
  let drawing = false;
  xs.forEach((x, i) => {
    if (!Number.isFinite(values[i]) || !Number.isFinite(x)) {
      drawing = false;
      return;
    }
    if (drawing) ctx.lineTo(px(x), py(values[i]));
    else ctx.moveTo(px(x), py(values[i]));
    drawing = true;
  });
  ctx.stroke();
  xs.forEach((x, i) => {
    if (Number.isFinite(values[i])) ctx.fillRect(px(x) - 2, py(values[i]) - 2, 4, 4);
  });
  Object.assign(canvas.dataset, { points: String(values.filter(Number.isFinite).length), xTitle, yTitle,
    max: String(Math.max(...values.filter(Number.isFinite)) || 0) });
}

// The unit to plot a length error in, by its largest value: {unit, scale} (m -> cm or mm).
export function lengthUnit(maxMetres) {
  if (maxMetres >= 1) return { unit: 'm', scale: 1 };
  if (maxMetres >= 0.01) return { unit: 'cm', scale: 100 };
  return { unit: 'mm', scale: 1000 };
}

// A figure with its plot; drawn once it is in the page (its size comes from the layout).
function plotFigure(id, caption, draw) {
  const canvas = el(`canvas.line-plot#${id}`, { width: 560, height: 240 });
  const figure = el('figure.plot', canvas, el('figcaption', caption));
  requestAnimationFrame(() => draw(canvas));
  return figure;
}

// The RPE per segment length: one row per length of the result (1 m and 10 m).
function segmentsTable(segments, pathLengthM) {
  return el('div.table-scroll', el('table#rpe-segments',
    el('thead', el('tr', ['Segment', 'Segments', 'Translation (RMSE)', 'Translation (mean, % of the segment)', 'Rotation (RMSE)']
      .map((h, i) => el(i ? 'th.num' : 'th', h)))),
    el('tbody', segments.map((s) => el('tr', { dataset: { length: String(s.length_m) } },
      el('td', `${Number(s.length_m.toPrecision(3))} m`),
      s.num_segments > 0 ? [
        el('td.num', String(s.num_segments)),
        el('td.num', formatLength(s.translation_rmse_m)),
        el('td.num', `${Number(s.translation_mean_percent.toPrecision(3))} %`),
        el('td.num', `${Number(s.rotation_rmse_deg.toPrecision(3))}°`),
      ] : el('td.muted', { colSpan: 4 }, `none: the path (${formatLength(pathLengthM)}) is shorter than ${Number(s.length_m.toPrecision(3))} m`))))));
}

// The card under the headline, or null without an evaluation (no ground truth).
export function slamErrorsCard(evaluation) {
  if (!evaluation) return null;
  const perFrame = evaluation.per_frame || {};
  const distance = perFrame.distance_m || [];
  const translation = perFrame.translation_error_m || [];
  const rotation = perFrame.rotation_error_deg || [];
  const { unit, scale } = lengthUnit(Math.max(0, ...translation.filter(Number.isFinite)));
  const plots = distance.length ? el('div.plots',
    plotFigure('translation-error-plot', 'Translation error of each frame after the alignment',
      (c) => drawLinePlot(c, distance, translation, { xTitle: 'distance travelled (m)', yTitle: `translation error (${unit})`, scale })),
    plotFigure('rotation-error-plot', 'Rotation error of each frame after the alignment',
      (c) => drawLinePlot(c, distance, rotation, { xTitle: 'distance travelled (m)', yTitle: 'rotation error (°)', colour: '#9333ea' })))
    : el('p.muted', 'This result has no per-frame errors.');
  const segments = Array.isArray(evaluation.rpe_segments) && evaluation.rpe_segments.length
    ? [el('h3', 'Relative pose error per segment of the ground-truth path'), segmentsTable(evaluation.rpe_segments, evaluation.path_length_m)]
    : [];
  return el('div.card#slam-errors', el('h2', 'Errors against the ground truth'),
    el('p.muted', `Over ${formatLength(evaluation.path_length_m)} of path, ${evaluation.num_poses ?? distance.length} poses; ` +
      'the estimate is aligned to the ground truth first (SE(3), as evo_ape does).'),
    plots, ...segments);
}
