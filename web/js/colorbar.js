// Colour bars for the images that encode a value (range panoramas, the calibration's
// uncertainty, coverage and the occupancy grid), drawn by the page with their scale and units,
// and the readers of what the bars need: the range panorama's float TIFF.
//
// The colour maps are OpenCV's, as the engine applies them (cv::applyColorMap): their 256 entries
// below were read from OpenCV 4.6 (COLORMAP_TURBO, COLORMAP_JET), as RGB hex.

import { el } from './ui.js';

const hexTable = (hex) => Array.from({ length: 256 }, (_, i) => [0, 2, 4].map((k) => parseInt(hex.substr(6 * i + k, 2), 16)));
export const TURBO = hexTable(
  '30123b32154333184a341b51351e5836215f37246638276d392a733a2d793b2f803c32863d358b3e38913f3b973f3e9c' +
  '4040a24143a74146ac4249b1424bb5434eba4451bf4454c34456c74559cb455ccf455ed34661d64664da4666dd4669e0' +
  '466be3476ee64771e94773eb4776ee4778f0477bf2467df44680f64682f84685fa4687fb458afc458cfd448ffe4391fe' +
  '4294ff4196ff4099ff3e9bfe3d9efe3ba0fd3aa3fc38a5fb37a8fa35abf833adf731aff52fb2f42eb4f22cb7f02ab9ee' +
  '28bceb27bee925c0e723c3e422c5e220c7df1fc9dd1ecbda1ccdd81bd0d51ad2d21ad4d019d5cd18d7ca18d9c818dbc5' +
  '18ddc218dec018e0bd19e2bb19e3b91ae4b61ce6b41de7b21fe9af20eaac22ebaa25eca727eea42aefa12cf09e2ff19b' +
  '32f29835f39438f4913cf58e3ff68a43f78746f8844af8804ef97d52fa7a55fa7659fb735dfc6f61fc6c65fd6969fd66' +
  '6dfe6271fe5f75fe5c79fe597dff5680ff5384ff5188ff4e8bff4b8fff4992ff4796fe4499fe429cfe409ffd3fa1fd3d' +
  'a4fc3ca7fc3aa9fb39acfb38affa37b1f936b4f836b7f735b9f635bcf534bef434c1f334c3f134c6f034c8ef34cbed34' +
  'cdec34d0ea34d2e935d4e735d7e535d9e436dbe236dde037dfdf37e1dd37e3db38e5d938e7d739e9d539ebd339ecd13a' +
  'eecf3aefcd3af1cb3af2c93af4c73af5c53af6c33af7c13af8be39f9bc39faba39fbb838fbb637fcb336fcb136fdae35' +
  'fdac34fea933fea732fea431fea130fe9e2ffe9b2dfe992cfe962bfe932afe9029fd8d27fd8a26fc8725fc8423fb8122' +
  'fb7e21fa7b1ff9781ef9751df8721cf76f1af66c19f56918f46617f36315f26014f15d13f05b12ef5811ed5510ec530f' +
  'eb500eea4e0de84b0ce7490ce5470be4450ae2430ae14109df3f08dd3d08dc3b07da3907d83706d63506d43305d23105' +
  'd02f05ce2d04cc2b04ca2a04c82803c52603c32503c12302be2102bc2002b91e02b71d02b41b01b21a01af1801ac1701' +
  'a91601a71401a41301a112019e10019b0f01980e01950d01920b018e0a018b09028808028507028106027e05027a0403',
);
export const JET = hexTable(
  '00008000008400008800008c00009000009400009800009c0000a00000a40000a80000ac0000b00000b40000b80000bc' +
  '0000c00000c40000c80000cc0000d00000d40000d80000dc0000e00000e40000e80000ec0000f00000f40000f80000fc' +
  '0000ff0004ff0008ff000cff0010ff0014ff0018ff001cff0020ff0024ff0028ff002cff0030ff0034ff0038ff003cff' +
  '0040ff0044ff0048ff004cff0050ff0054ff0058ff005cff0060ff0064ff0068ff006cff0070ff0074ff0078ff007cff' +
  '0080ff0084ff0088ff008cff0090ff0094ff0098ff009cff00a0ff00a4ff00a8ff00acff00b0ff00b4ff00b8ff00bcff' +
  '00c0ff00c4ff00c8ff00ccff00d0ff00d4ff00d8ff00dcff00e0ff00e4ff00e8ff00ecff00f0ff00f4ff00f8ff00fcff' +
  '02fffe06fffa0afff60efff212ffee16ffea1affe61effe222ffde26ffda2affd62effd232ffce36ffca3affc63effc2' +
  '42ffbe46ffba4affb64effb252ffae56ffaa5affa65effa262ff9e66ff9a6aff966eff9272ff8e76ff8a7aff867eff82' +
  '82ff7e86ff7a8aff768eff7292ff6e96ff6a9aff669eff62a2ff5ea6ff5aaaff56aeff52b2ff4eb6ff4abaff46beff42' +
  'c2ff3ec6ff3acaff36ceff32d2ff2ed6ff2adaff26deff22e2ff1ee6ff1aeaff16eeff12f2ff0ef6ff0afaff06feff01' +
  'fffc00fff800fff400fff000ffec00ffe800ffe400ffe000ffdc00ffd800ffd400ffd000ffcc00ffc800ffc400ffc000' +
  'ffbc00ffb800ffb400ffb000ffac00ffa800ffa400ffa000ff9c00ff9800ff9400ff9000ff8c00ff8800ff8400ff8000' +
  'ff7c00ff7800ff7400ff7000ff6c00ff6800ff6400ff6000ff5c00ff5800ff5400ff5000ff4c00ff4800ff4400ff4000' +
  'ff3c00ff3800ff3400ff3000ff2c00ff2800ff2400ff2000ff1c00ff1800ff1400ff1000ff0c00ff0800ff0400ff0000' +
  'fc0000f80000f40000f00000ec0000e80000e40000e00000dc0000d80000d40000d00000cc0000c80000c40000c00000' +
  'bc0000b80000b40000b00000ac0000a80000a40000a000009c00009800009400009000008c0000880000840000800000',
);

// Ticks at 1, 2, 5 x 10^k inside [min, max] (logarithmic) or at a round step (linear).
export function ticks(min, max, log, count = 5) {
  if (!(max > min)) return [min];
  if (log) {
    const out = [];
    for (let e = Math.floor(Math.log10(min)); e <= Math.ceil(Math.log10(max)); e += 1) {
      for (const m of [1, 2, 5]) {
        const v = m * 10 ** e;
        if (v >= min * 0.999 && v <= max * 1.001) out.push(v);
      }
    }
    return out.length >= 2 ? out : [min, max];
  }
  const raw = (max - min) / count;
  const power = 10 ** Math.floor(Math.log10(raw));
  const step = [1, 2, 5, 10].map((m) => m * power).find((s) => s >= raw) || raw;
  const out = [];
  for (let v = Math.ceil(min / step) * step; v <= max + step * 1e-9; v += step) out.push(Number(v.toPrecision(12)));
  return out;
}

const tickText = (v) => (Math.abs(v) >= 100 || Number.isInteger(v) ? String(Math.round(v)) : String(Number(v.toPrecision(2))));

// A continuous colour bar: `colourAt(t)` gives the [r, g, b] of the fraction t in [0, 1] from
// `min` to `max` (in `unit`), on a logarithmic axis when `log`. The canvas carries its scale in
// data attributes (min, max, unit) for tests and readers of the page.
export function colourBar({ colourAt, min, max, unit, log = false, title, id, ends = [] }) {
  const width = 360;
  const height = 46;
  const canvas = el('canvas.colour-bar-canvas', { width, height });
  const ctx = canvas.getContext('2d');
  const left = 10;
  const barWidth = width - 2 * left;
  for (let x = 0; x < barWidth; x += 1) {
    const [r, g, b] = colourAt(x / (barWidth - 1));
    ctx.fillStyle = `rgb(${r},${g},${b})`;
    ctx.fillRect(left + x, 4, 1, 16);
  }
  ctx.strokeStyle = '#444';
  ctx.strokeRect(left - 0.5, 3.5, barWidth + 1, 17);
  ctx.fillStyle = '#222';
  ctx.font = '11px system-ui, sans-serif';
  ctx.textAlign = 'center';
  const position = (v) => (log ? (Math.log(v) - Math.log(min)) / (Math.log(max) - Math.log(min)) : (v - min) / (max - min));
  for (const v of ticks(min, max, log)) {
    const x = left + position(v) * (barWidth - 1);
    ctx.fillRect(Math.round(x), 20, 1, 5);
    ctx.fillText(tickText(v), Math.min(width - 14, Math.max(14, x)), 37);
  }
  return el(`figure.colour-bar${id ? `#${id}` : ''}`, {
    dataset: { min: String(min), max: String(max), unit, scale: log ? 'log' : 'linear' },
  }, el('figcaption', title, ` (${unit}${log ? ', logarithmic' : ''})`), canvas,
  ends.length ? el('div.colour-bar-ends', ends.map((text) => el('span', text))) : null);
}

// A key of categories: [{colour, label}], for images whose colours name classes.
export function colourKey({ items, title, id }) {
  return el(`figure.colour-bar.colour-key${id ? `#${id}` : ''}`, { dataset: { unit: 'category' } },
    el('figcaption', title),
    el('ul.legend', items.map(({ colour, label, dot }) => el('li.legend-item',
      el(dot ? 'span.swatch.dot' : 'span.swatch', { style: `background: ${colour}` }), label))));
}

// The range panorama's colours (engine/dense/range_io.cc): the logarithm of the range between
// the 2nd and 98th percentiles of every 8th known cell, TURBO reversed (near red, far blue).
export function rangeColourBar(scale, id) {
  return colourBar({
    colourAt: (t) => TURBO[Math.round(255 * (1 - t))],
    min: scale.near_m,
    max: scale.far_m,
    unit: 'm',
    log: true,
    title: 'Range from cam0\'s centre',
    id,
    ends: [`near: ${Number(scale.near_m.toPrecision(3))} m`, 'black: no depth', `far: ${Number(scale.far_m.toPrecision(3))} m`],
  });
}

// The calibration's uncertainty image (engine/calib/coverage.cc): JET from 0 to the largest
// uncertainty over the disk, in pixels.
export function uncertaintyColourBar(maxPx, id) {
  return colourBar({
    colourAt: (t) => JET[Math.round(255 * t)],
    min: 0,
    max: maxPx,
    unit: 'px',
    title: 'Projection uncertainty (1 σ)',
    id,
  });
}

// Reads a little- or big-endian TIFF of one 32-bit float sample per pixel, uncompressed, in
// strips (what OpenCV writes for a CV_32FC1 image): {width, height, data: Float32Array}.
export function parseFloatTiff(buffer) {
  const bytes = buffer instanceof Uint8Array ? buffer : new Uint8Array(buffer);
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const little = view.getUint16(0) === 0x4949;
  if (!little && view.getUint16(0) !== 0x4d4d) throw new Error('not a TIFF file');
  const u16 = (o) => view.getUint16(o, little);
  const u32 = (o) => view.getUint32(o, little);
  const ifd = u32(4);
  const tags = {};
  for (let i = 0; i < u16(ifd); i += 1) {
    const entry = ifd + 2 + 12 * i;
    const [tag, type, count] = [u16(entry), u16(entry + 2), u32(entry + 4)];
    const size = type === 3 ? 2 : 4;
    const at = count * size <= 4 ? entry + 8 : u32(entry + 8);
    tags[tag] = Array.from({ length: count }, (_, k) => (size === 2 ? u16(at + 2 * k) : u32(at + 4 * k)));
  }
  const [width] = tags[256];
  const [height] = tags[257];
  if ((tags[259] || [1])[0] !== 1) throw new Error('the TIFF is compressed');
  if ((tags[258] || [0])[0] !== 32 || (tags[339] || [1])[0] !== 3 || (tags[277] || [1])[0] !== 1) {
    throw new Error('the TIFF does not hold one 32-bit float per pixel');
  }
  const data = new Float32Array(width * height);
  let index = 0;
  tags[273].forEach((offset, s) => {
    for (let o = offset; o < offset + tags[279][s] && index < data.length; o += 4) data[index++] = view.getFloat32(o, little);
  });
  return { width, height, data };
}

// The range preview's scale as the engine computes it from the float panorama: {near_m, far_m},
// or null when no cell has a range.
export function rangePreviewScale(ranges) {
  const known = [];
  let seen = 0;
  for (const r of ranges) if (r > 0 && seen++ % 8 === 0) known.push(r);
  if (!known.length) return null;
  known.sort((a, b) => a - b);
  const at = (q) => known[Math.floor(q * (known.length - 1))];
  const lo = Math.log(at(0.02));
  const hi = Math.max(Math.log(at(0.98)), lo + 1e-3);
  return { near_m: Math.exp(lo), far_m: Math.exp(hi) };
}
