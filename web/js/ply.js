// A small PLY reader for point clouds: binary little-endian (what omnirig writes) and ASCII.
// Reads the "vertex" element into flat typed arrays (no per-point objects), so that two million
// points parse in a fraction of a second and go straight into one three.js BufferGeometry.

const TYPES = {
  char: ['getInt8', 1], int8: ['getInt8', 1], uchar: ['getUint8', 1], uint8: ['getUint8', 1],
  short: ['getInt16', 2], int16: ['getInt16', 2], ushort: ['getUint16', 2], uint16: ['getUint16', 2],
  int: ['getInt32', 4], int32: ['getInt32', 4], uint: ['getUint32', 4], uint32: ['getUint32', 4],
  float: ['getFloat32', 4], float32: ['getFloat32', 4], double: ['getFloat64', 8], float64: ['getFloat64', 8],
};

// Parses the header; returns {format, elements: [{name, count, properties: [{name, type, list}]}], bodyOffset}.
export function parsePlyHeader(bytes) {
  const probe = new TextDecoder('latin1').decode(bytes.subarray(0, Math.min(bytes.length, 65536)));
  const end = probe.indexOf('end_header');
  if (!probe.startsWith('ply') || end < 0) throw new Error('not a PLY file (no "ply" magic or no end_header)');
  const newline = probe.indexOf('\n', end);
  const header = { format: '', elements: [], comments: [], bodyOffset: newline + 1 };
  for (const raw of probe.slice(0, end).split('\n')) {
    const words = raw.trim().split(/\s+/);
    if (words[0] === 'format') header.format = words[1];
    else if (words[0] === 'comment') header.comments.push(raw.trim().slice(8));
    else if (words[0] === 'element') header.elements.push({ name: words[1], count: Number(words[2]), properties: [] });
    else if (words[0] === 'property') {
      const element = header.elements[header.elements.length - 1];
      if (!element) throw new Error('PLY property before any element');
      element.properties.push(words[1] === 'list'
        ? { list: true, countType: words[2], type: words[3], name: words[4] }
        : { list: false, type: words[1], name: words[2] });
    }
  }
  return header;
}

// Returns {count, positions: Float32Array(3n), colors: Uint8Array(3n) | null,
// extra: {name: Float32Array(n)} for other scalar vertex properties (e.g. observation counts)}.
export function parsePly(buffer) {
  const bytes = buffer instanceof Uint8Array ? buffer : new Uint8Array(buffer);
  const header = parsePlyHeader(bytes);
  const vertex = header.elements.find((e) => e.name === 'vertex');
  if (!vertex) throw new Error('PLY has no vertex element');
  if (header.format === 'ascii') return readAscii(bytes, header, vertex);
  if (header.format !== 'binary_little_endian') throw new Error(`PLY format ${header.format} is not supported`);
  return readBinary(bytes, header, vertex);
}

function outputs(vertex) {
  const n = vertex.count;
  const names = vertex.properties.map((p) => p.name);
  for (const axis of ['x', 'y', 'z']) if (!names.includes(axis)) throw new Error(`PLY vertex has no ${axis}`);
  const colorNames = ['red', 'green', 'blue'].every((c) => names.includes(c)) ? ['red', 'green', 'blue']
    : ['r', 'g', 'b'].every((c) => names.includes(c)) ? ['r', 'g', 'b'] : null;
  const out = { count: n, positions: new Float32Array(3 * n), colors: colorNames ? new Uint8Array(3 * n) : null, extra: {} };
  // Each scalar property writes into (array, stride, offset).
  const targets = vertex.properties.map((p) => {
    if (p.list) return null;
    const axis = ['x', 'y', 'z'].indexOf(p.name);
    if (axis >= 0) return [out.positions, 3, axis];
    const c = colorNames ? colorNames.indexOf(p.name) : -1;
    if (c >= 0) return [out.colors, 3, c];
    out.extra[p.name] = new Float32Array(n);
    return [out.extra[p.name], 1, 0];
  });
  return { out, targets };
}

function elementSize(element) {
  let size = 0;
  for (const p of element.properties) {
    if (p.list) return -1;
    size += TYPES[p.type][1];
  }
  return size;
}

function readBinary(bytes, header, vertex) {
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  let offset = header.bodyOffset;
  for (const element of header.elements) {
    if (element === vertex) break;
    const size = elementSize(element);
    if (size < 0) throw new Error(`PLY element ${element.name} with lists before the vertices is not supported`);
    offset += size * element.count;
  }
  const { out, targets } = outputs(vertex);
  for (const p of vertex.properties) if (p.list) throw new Error('PLY vertex lists are not supported');
  const stride = elementSize(vertex);
  if (offset + stride * vertex.count > bytes.byteLength) throw new Error('PLY file is truncated');
  // One small reader function per property, made once, so the loop does no type dispatch.
  let within = 0;
  const readers = [];
  vertex.properties.forEach((p, i) => {
    const [method, size] = TYPES[p.type];
    const at = within;
    within += size;
    const [array, step, k] = targets[i];
    if (size === 1 && method === 'getUint8') readers.push((base, n) => { array[n * step + k] = bytes[base + at]; });
    else readers.push((base, n) => { array[n * step + k] = view[method](base + at, true); });
  });
  const floatXyz = vertex.properties.slice(0, 3).every((p, i) => p.name === 'xyz'[i] && TYPES[p.type][0] === 'getFloat32');
  const positions = out.positions;
  const first = floatXyz ? 3 : 0;
  for (let i = 0; i < vertex.count; i += 1) {
    const base = offset + i * stride;
    if (floatXyz) {  // the common layout, read without the generic readers
      positions[3 * i] = view.getFloat32(base, true);
      positions[3 * i + 1] = view.getFloat32(base + 4, true);
      positions[3 * i + 2] = view.getFloat32(base + 8, true);
    }
    for (let r = first; r < readers.length; r += 1) readers[r](base, i);
  }
  return out;
}

function readAscii(bytes, header, vertex) {
  const text = new TextDecoder().decode(bytes.subarray(header.bodyOffset));
  const lines = text.split('\n');
  let line = 0;
  for (const element of header.elements) {
    if (element === vertex) break;
    line += element.count;
  }
  const { out, targets } = outputs(vertex);
  for (let i = 0; i < vertex.count; i += 1) {
    const words = (lines[line + i] || '').trim().split(/\s+/);
    if (words.length < vertex.properties.length) throw new Error(`PLY vertex ${i} is incomplete`);
    targets.forEach((t, k) => {
      if (t) t[0][i * t[1] + t[2]] = Number(words[k]);
    });
  }
  return out;
}
