// A bar chart on a canvas (per-image errors), without a charting library.

// bars: [{label, value, muted, note}]; options: {reference (a horizontal line), unit}.
export function drawBarChart(canvas, bars, options = {}) {
  const ratio = window.devicePixelRatio || 1;
  const width = canvas.clientWidth || canvas.width;
  const height = canvas.clientHeight || canvas.height;
  canvas.width = Math.round(width * ratio);
  canvas.height = Math.round(height * ratio);
  const ctx = canvas.getContext('2d');
  ctx.scale(ratio, ratio);
  ctx.clearRect(0, 0, width, height);
  const left = 48;
  const bottom = 34;
  const top = 12;
  const plotW = width - left - 8;
  const plotH = height - top - bottom;
  const maxValue = Math.max(1e-9, options.reference || 0, ...bars.map((b) => b.value || 0)) * 1.1;
  const y = (v) => top + plotH * (1 - v / maxValue);

  ctx.font = '11px system-ui, sans-serif';
  ctx.strokeStyle = '#dde1e6';
  ctx.fillStyle = '#69727d';
  ctx.textAlign = 'right';
  ctx.textBaseline = 'middle';
  for (const tick of niceTicks(maxValue)) {
    ctx.beginPath();
    ctx.moveTo(left, y(tick));
    ctx.lineTo(left + plotW, y(tick));
    ctx.stroke();
    ctx.fillText(tick.toFixed(tick < 1 ? 2 : 1), left - 6, y(tick));
  }
  ctx.save();
  ctx.translate(12, top + plotH / 2);
  ctx.rotate(-Math.PI / 2);
  ctx.textAlign = 'center';
  ctx.fillText(options.unit || '', 0, 0);
  ctx.restore();

  const slot = plotW / Math.max(1, bars.length);
  const barW = Math.max(1, slot * 0.7);
  bars.forEach((bar, i) => {
    const x = left + i * slot + (slot - barW) / 2;
    ctx.fillStyle = bar.muted ? '#cbd5e1' : '#3b82f6';
    const h = bar.muted ? 4 : Math.max(1, y(0) - y(bar.value || 0));
    ctx.fillRect(x, y(0) - h, barW, h);
    if (bar.note) {
      ctx.fillStyle = '#b91c1c';
      ctx.textAlign = 'center';
      ctx.fillText(bar.note, x + barW / 2, y(0) - 12);
    }
  });
  // Labels, thinned so that they do not overlap.
  const every = Math.max(1, Math.ceil(bars.length / Math.max(1, Math.floor(plotW / 60))));
  ctx.fillStyle = '#69727d';
  ctx.textAlign = 'center';
  ctx.textBaseline = 'top';
  bars.forEach((bar, i) => {
    if (i % every) return;
    const label = bar.label.length > 12 ? `…${bar.label.slice(-11)}` : bar.label;
    ctx.fillText(label, left + i * slot + slot / 2, y(0) + 6);
  });
  if (options.reference) {
    ctx.strokeStyle = '#b45309';
    ctx.setLineDash([5, 4]);
    ctx.beginPath();
    ctx.moveTo(left, y(options.reference));
    ctx.lineTo(left + plotW, y(options.reference));
    ctx.stroke();
    ctx.setLineDash([]);
  }
}

function niceTicks(maxValue) {
  const raw = maxValue / 4;
  const magnitude = 10 ** Math.floor(Math.log10(raw));
  const step = [1, 2, 5, 10].map((m) => m * magnitude).find((s) => s >= raw) || raw;
  const ticks = [];
  for (let t = 0; t <= maxValue + 1e-12; t += step) ticks.push(t);
  return ticks;
}
