// Writes MCAP files with npm's @mcap/core (Foxglove's writer) and CDR messages with
// @foxglove/cdr, for tests. usage: node write_mcap.mjs OUT_DIR
//
// OUT_DIR/images_lz4.mcap, images_zstd.mcap: sensor_msgs/msg/Image (mono8, rgb8, bayer_rggb8)
// and CompressedImage (png) in lz4 / zstd chunks, with summary and message indexes;
// images_bare.mcap: lz4 chunks, no summary and no message indexes (read by a linear scan);
// OUT_DIR/messages/*.cdr: single CDR messages for the decoder's tests. Content as in
// write_ros1_bags.py (the same formulas).
import { createRequire } from "node:module";
import fs from "node:fs";
import path from "node:path";
import { fileURLToPath } from "node:url";

const here = path.dirname(fileURLToPath(import.meta.url));
// The packages live in web/node_modules (web/package.json's devDependencies).
const require = createRequire(path.join(here, "../../web/package.json"));
const { McapWriter } = require("@mcap/core");
const { CdrWriter } = require("@foxglove/cdr");
const lz4 = require("lz4js");
const zstd = require("@foxglove/wasm-zstd");

const WIDTH = 32, HEIGHT = 24, T0_S = 1700000000, FRAMES = 10, PERIOD_NS = 50000000;
const channelValue = (x, y, c) => (x * 7 + y * 13 + c * 50) % 256;
const rgbPixel = (x, y) => [4 * x + 40, 4 * y + 20, 128];

function pixels(encoding) {
  const out = [];
  for (let y = 0; y < HEIGHT; ++y) {
    for (let x = 0; x < WIDTH; ++x) {
      const [r, g, b] = [0, 1, 2].map((c) => channelValue(x, y, c));
      if (encoding === "mono8") out.push(r);
      else if (encoding === "mono16") {
        const v = (channelValue(x, y, 0) * 257 + 3) & 0xffff;
        out.push(v & 0xff, v >> 8);
      } else if (encoding === "rgb8") out.push(r, g, b);
      else if (encoding === "bgr8") out.push(b, g, r);
      else if (encoding === "rgba8") out.push(r, g, b, 255);
      else if (encoding === "bgra8") out.push(b, g, r, 255);
      else if (encoding.startsWith("bayer_")) {
        const colour = encoding.slice(6, 10)[(y % 2) * 2 + (x % 2)];
        out.push(rgbPixel(x, y)["rgb".indexOf(colour)]);
      } else throw new Error(encoding);
    }
  }
  return Uint8Array.from(out);
}

function writeHeader(writer, i) {
  writer.int32(T0_S);  // builtin_interfaces/Time: int32 sec, uint32 nanosec
  writer.uint32(i * PERIOD_NS);
  writer.string("cam0");
}

function imageCdr(encoding, i) {
  const data = pixels(encoding);
  const writer = new CdrWriter();
  writeHeader(writer, i);
  writer.uint32(HEIGHT);
  writer.uint32(WIDTH);
  writer.string(encoding);
  writer.uint8(0);  // is_bigendian
  writer.uint32(data.length / HEIGHT);  // step
  writer.uint8Array(data, true);
  return writer.data;
}

function compressedCdr(format, i) {
  const writer = new CdrWriter();
  writeHeader(writer, i);
  writer.string(format);
  writer.uint8Array(new Uint8Array(fs.readFileSync(path.join(here, "gradient." + format))), true);
  return writer.data;
}

const IMAGE_DEF = "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n" +
  "uint8 is_bigendian\nuint32 step\nuint8[] data\n";
const COMPRESSED_DEF = "std_msgs/Header header\nstring format\nuint8[] data\n";

class MemoryWritable {
  chunks = [];
  size = 0n;
  position() { return this.size; }
  async write(buffer) {
    this.chunks.push(Buffer.from(buffer));
    this.size += BigInt(buffer.byteLength);
  }
}

async function writeMcap(file, options) {
  const writable = new MemoryWritable();
  const writer = new McapWriter({ writable, chunkSize: 8192, ...options });
  await writer.start({ profile: "ros2", library: "omnirig tests" });
  const encoder = new TextEncoder();
  const image = await writer.registerSchema(
    { name: "sensor_msgs/msg/Image", encoding: "ros2msg", data: encoder.encode(IMAGE_DEF) });
  const compressed = await writer.registerSchema(
    { name: "sensor_msgs/msg/CompressedImage", encoding: "ros2msg", data: encoder.encode(COMPRESSED_DEF) });
  const channels = {};
  for (const [topic, schemaId] of [["/cam0/image_raw", image], ["/cam1/image_raw", image],
                                   ["/bayer/image_raw", image], ["/cam0/image_raw/compressed", compressed]]) {
    channels[topic] = await writer.registerChannel(
      { topic, schemaId, messageEncoding: "cdr", metadata: new Map() });
  }
  for (let i = 0; i < FRAMES; ++i) {
    const logTime = BigInt(T0_S) * 1000000000n + BigInt(i * PERIOD_NS + 5000000);
    const add = (topic, data) => writer.addMessage(
      { channelId: channels[topic], sequence: i, logTime, publishTime: logTime, data });
    await add("/cam0/image_raw", imageCdr("mono8", i));
    await add("/cam1/image_raw", imageCdr("rgb8", i));
    await add("/bayer/image_raw", imageCdr("bayer_rggb8", i));
    await add("/cam0/image_raw/compressed", compressedCdr("png", i));
  }
  await writer.end();
  fs.writeFileSync(file, Buffer.concat(writable.chunks));
}

// Large files for bench/recording_index_bench.cc (--bench SIZE_MB): two topics of 1280x1024
// mono8 images at 20 Hz (a gradient with 3 bits of noise), written straight to the file.
class FileWritable {
  constructor(file) { this.fd = fs.openSync(file, "w"); this.size = 0n; }
  position() { return this.size; }
  async write(buffer) {
    fs.writeSync(this.fd, buffer);
    this.size += BigInt(buffer.byteLength);
  }
}

async function writeBenchMcap(file, sizeMb, compressChunk) {
  const W = 1280, H = 1024;
  const pool = [];
  for (let k = 0; k < 8; ++k) {
    const data = new Uint8Array(W * H);
    for (let p = 0; p < data.length; ++p) data[p] = (p & 0xf8) | ((Math.random() * 8) | 0);
    pool.push(data);
  }
  const writable = new FileWritable(file);
  // Chunks under lz4js's 4 MiB block: its frames of several blocks do not decompress (with
  // liblz4's reference decoder either), so one chunk holds one or two images.
  const writer = new McapWriter({ writable, chunkSize: 1 << 20, compressChunk });
  await writer.start({ profile: "ros2", library: "omnirig bench" });
  const schemaId = await writer.registerSchema(
    { name: "sensor_msgs/msg/Image", encoding: "ros2msg", data: new TextEncoder().encode(IMAGE_DEF) });
  const channels = [];
  for (const topic of ["/cam0/image_raw", "/cam1/image_raw"]) {
    channels.push(await writer.registerChannel({ topic, schemaId, messageEncoding: "cdr", metadata: new Map() }));
  }
  const count = Math.max(2, Math.floor(sizeMb * 1048576 / (W * H) / 2));
  for (let i = 0; i < count; ++i) {
    const logTime = BigInt(T0_S) * 1000000000n + BigInt(i * PERIOD_NS);
    for (let c = 0; c < 2; ++c) {
      const cdr = new CdrWriter();
      writeHeader(cdr, i);
      cdr.uint32(H); cdr.uint32(W); cdr.string("mono8"); cdr.uint8(0); cdr.uint32(W);
      cdr.uint8Array(pool[(i + 3 * c) % 8], true);
      await writer.addMessage({ channelId: channels[c], sequence: i, logTime, publishTime: logTime, data: cdr.data });
    }
  }
  await writer.end();
  fs.closeSync(writable.fd);
}

const out = process.argv[2];
fs.mkdirSync(path.join(out, "messages"), { recursive: true });
await zstd.isLoaded;
if (process.argv[3] === "--bench") {
  const sizeMb = Number(process.argv[4]);
  await writeBenchMcap(path.join(out, "bench_lz4.mcap"), sizeMb,
                       (data) => ({ compression: "lz4", compressedData: lz4.compress(data) }));
  await writeBenchMcap(path.join(out, "bench_zstd.mcap"), sizeMb,
                       (data) => ({ compression: "zstd", compressedData: zstd.compress(data, 3) }));
  process.exit(0);
}
const lz4Chunk = (data) => ({ compression: "lz4", compressedData: lz4.compress(data) });
const zstdChunk = (data) => ({ compression: "zstd", compressedData: zstd.compress(data, 3) });
await writeMcap(path.join(out, "images_lz4.mcap"), { compressChunk: lz4Chunk });
await writeMcap(path.join(out, "images_zstd.mcap"), { compressChunk: zstdChunk });
await writeMcap(path.join(out, "images_bare.mcap"), {
  compressChunk: lz4Chunk, useMessageIndex: false, useChunkIndex: false, useStatistics: false,
  useSummaryOffsets: false, repeatSchemas: false, repeatChannels: false,
  useAttachmentIndex: false, useMetadataIndex: false });
for (const encoding of ["mono8", "mono16", "rgb8", "bgr8", "rgba8", "bgra8", "bayer_rggb8",
                        "bayer_bggr8", "bayer_gbrg8", "bayer_grbg8"]) {
  fs.writeFileSync(path.join(out, "messages", encoding + ".cdr"), imageCdr(encoding, 3));
}
for (const format of ["png", "jpeg"]) {
  fs.writeFileSync(path.join(out, "messages", "compressed_" + format + ".cdr"), compressedCdr(format, 3));
}
