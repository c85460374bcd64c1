// Writes a stereo sequence as ROS 2 records it, for tests: an MCAP file with npm's @mcap/core
// (Foxglove's writer) and its messages as CDR files (@foxglove/cdr) for write_stereo_db3.py.
//
// usage: node write_stereo_ros2.mjs FRAMES_DIR OUT.mcap CDR_DIR
//
// FRAMES_DIR/manifest.txt as for write_stereo_bag.py: "SEC NSEC WIDTH HEIGHT ENCODING CAM0 CAM1"
// per stereo frame, CAM0 raw pixels in ENCODING (mono8 or bgr8), CAM1 a PNG file. cam0 becomes
// /cam0/image_raw (sensor_msgs/msg/Image, stamped SEC.NSEC), cam1
// /cam1/image_raw/compressed (sensor_msgs/msg/CompressedImage, png, stamped 1 ms later), each
// logged 5 ms after its stamp, in zstd chunks. CDR_DIR/NNNNN_cam0.cdr and NNNNN_cam1.cdr hold
// the same messages, and CDR_DIR/index.txt one line per message: "TOPIC LOG_TIME_NS FILE".
import { createRequire } from "node:module";
import fs from "node:fs";
import path from "node:path";
import { fileURLToPath } from "node:url";

const here = path.dirname(fileURLToPath(import.meta.url));
const require = createRequire(path.join(here, "../../web/package.json"));
const { McapWriter } = require("@mcap/core");
const { CdrWriter } = require("@foxglove/cdr");
const zstd = require("@foxglove/wasm-zstd");

const IMAGE_DEF = "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n" +
  "uint8 is_bigendian\nuint32 step\nuint8[] data\n";
const COMPRESSED_DEF = "std_msgs/Header header\nstring format\nuint8[] data\n";

function header(writer, stampNs, frameId) {
  writer.int32(Number(stampNs / 1000000000n));
  writer.uint32(Number(stampNs % 1000000000n));
  writer.string(frameId);
}

function imageCdr(stampNs, width, height, encoding, data) {
  const writer = new CdrWriter();
  header(writer, stampNs, "cam0");
  writer.uint32(height);
  writer.uint32(width);
  writer.string(encoding);
  writer.uint8(0);  // is_bigendian
  writer.uint32((encoding === "bgr8" ? 3 : 1) * width);
  writer.uint8Array(data, true);
  return writer.data;
}

function compressedCdr(stampNs, data) {
  const writer = new CdrWriter();
  header(writer, stampNs, "cam1");
  writer.string("png");
  writer.uint8Array(data, true);
  return writer.data;
}

class MemoryWritable {
  chunks = [];
  size = 0n;
  position() { return this.size; }
  async write(buffer) {
    this.chunks.push(Buffer.from(buffer));
    this.size += BigInt(buffer.byteLength);
  }
}

const [framesDir, outMcap, cdrDir] = process.argv.slice(2);
await zstd.isLoaded;
fs.mkdirSync(cdrDir, { recursive: true });
const lines = fs.readFileSync(path.join(framesDir, "manifest.txt"), "utf8")
  .split("\n").filter((line) => line.trim()).map((line) => line.trim().split(/\s+/));
const writable = new MemoryWritable();
const writer = new McapWriter({
  writable, chunkSize: 1 << 20,
  compressChunk: (data) => ({ compression: "zstd", compressedData: zstd.compress(data, 3) }) });
await writer.start({ profile: "ros2", library: "omnirig tests" });
const encoder = new TextEncoder();
const image = await writer.registerSchema(
  { name: "sensor_msgs/msg/Image", encoding: "ros2msg", data: encoder.encode(IMAGE_DEF) });
const compressed = await writer.registerSchema(
  { name: "sensor_msgs/msg/CompressedImage", encoding: "ros2msg", data: encoder.encode(COMPRESSED_DEF) });
const cam0 = await writer.registerChannel(
  { topic: "/cam0/image_raw", schemaId: image, messageEncoding: "cdr", metadata: new Map() });
const cam1 = await writer.registerChannel(
  { topic: "/cam1/image_raw/compressed", schemaId: compressed, messageEncoding: "cdr", metadata: new Map() });
const index = [];
for (const [i, [sec, nsec, width, height, encoding, raw, png]] of lines.entries()) {
  const stampNs = BigInt(sec) * 1000000000n + BigInt(nsec);
  const messages = [
    [cam0, "/cam0/image_raw", stampNs + 5000000n,
     imageCdr(stampNs, Number(width), Number(height), encoding, fs.readFileSync(path.join(framesDir, raw)))],
    [cam1, "/cam1/image_raw/compressed", stampNs + 6000000n,
     compressedCdr(stampNs + 1000000n, fs.readFileSync(path.join(framesDir, png)))],
  ];
  for (const [c, [channelId, topic, logTime, data]] of messages.entries()) {
    await writer.addMessage({ channelId, sequence: i, logTime, publishTime: logTime, data });
    const file = String(i).padStart(5, "0") + "_cam" + c + ".cdr";
    fs.writeFileSync(path.join(cdrDir, file), data);
    index.push(topic + " " + logTime + " " + file);
  }
}
await writer.end();
fs.writeFileSync(outMcap, Buffer.concat(writable.chunks));
fs.writeFileSync(path.join(cdrDir, "index.txt"), index.join("\n") + "\n");
