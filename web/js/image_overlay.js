// An image with an SVG overlay in the image's own pixel coordinates, reporting clicks as pixels.
// Pixel convention (as the engine's): the centre of the top-left pixel is (0, 0), so a click at
// the top-left corner of the image is (-0.5, -0.5).

import { apiImage, el } from './ui.js';

const SVG = 'http://www.w3.org/2000/svg';

function svgEl(tag, attrs) {
  const node = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  return node;
}

// onClick(u, v) with (u, v) in image pixels. Returns {node, img, svg, clear, marker, polyline}.
export function clickableImage(src, onClick) {
  const img = apiImage(src, { alt: '', draggable: false });
  const svg = svgEl('svg', { preserveAspectRatio: 'none' });
  const node = el('div.clickable-image', img);
  node.append(svg);
  const size = () => [img.naturalWidth || 1, img.naturalHeight || 1];
  const fitViewBox = () => {
    const [w, h] = size();
    svg.setAttribute('viewBox', `-0.5 -0.5 ${w} ${h}`);
  };
  img.addEventListener('load', fitViewBox);
  if (img.complete) fitViewBox();
  node.addEventListener('click', (e) => {
    if (!img.naturalWidth) return;
    const rect = img.getBoundingClientRect();
    const [w, h] = size();
    const u = ((e.clientX - rect.left) / rect.width) * w - 0.5;
    const v = ((e.clientY - rect.top) / rect.height) * h - 0.5;
    onClick(u, v);
  });
  // Stroke widths scale with the image so that lines stay visible on large images.
  const stroke = () => Math.max(1.5, size()[0] / 400);
  return {
    node,
    img,
    svg,
    loaded: () => (img.complete && img.naturalWidth ? Promise.resolve() :
      new Promise((resolve, reject) => {
        img.addEventListener('load', resolve, { once: true });
        img.addEventListener('error', () => reject(new Error(`could not load ${src}`)), { once: true });
      })),
    clear: () => svg.replaceChildren(),
    marker(u, v, label, color = '#ef4444') {
      const r = stroke() * 3;
      svg.append(svgEl('circle', { cx: u, cy: v, r, fill: 'none', stroke: color, 'stroke-width': stroke(), class: 'marker' }));
      if (label) {
        const text = svgEl('text', { x: u + r * 1.3, y: v - r * 1.3, fill: color, 'font-size': r * 4, 'font-family': 'sans-serif' });
        text.textContent = label;
        svg.append(text);
      }
    },
    polyline(points, color = '#22d3ee', cls = 'curve') {
      svg.append(svgEl('polyline', { points: points.map(([u, v]) => `${u},${v}`).join(' '), fill: 'none',
        stroke: color, 'stroke-width': stroke(), 'stroke-linejoin': 'round', class: cls }));
    },
  };
}
