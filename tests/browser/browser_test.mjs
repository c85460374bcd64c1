// Browser tests of the web page: the real `omnirig serve` on an ephemeral loopback port with a
// temporary data folder, Debian's chromium (headless) driven by playwright-core.
//
//   node browser_test.mjs --omnirig BUILD/server/omnirig --step STEP [--out DIR] [--url URL]
//
// STEP is one of:
//   datasets    create a dataset, upload a folder (cam0/ kept), resume (nothing re-sent),
//               thumbnails, a non-image refused with the server's JSON message shown, a video
//               sent in chunks resuming where the server's part ends
//   calibration upload a calibration set, submit a calibration job from the form, watch its
//               progress reach done, read the report (RMS, intrinsics, chart, overlays), the
//               coverage advice by ring and clock at a middle (six views) and a low (three) coverage
//   stereo      upload a stereo board set, run relative_pose, read the report, click a pixel in
//               each image and check that an epipolar curve is drawn in the other; then a
//               stereo_reconstruct job with that rig, its cloud drawn in the 3D viewer; then one
//               pair on a finer grid: its preview under 2 M points and 20 MB loaded first, the
//               full cloud on request, colour by height and confidence
//   viewer_ply  open a 2-million-point PLY in the 3D viewer, check from the canvas pixels that
//               points were drawn
//   viewer_slam a slam job on a synthetic sequence: cloud, trajectory, top view against the
//               ground truth and its legend, per-frame statistics, the headline with units, the
//               errors plotted against the distance travelled, RPE per segment (needs omnirig
//               synth); then
//               loops and states injected into the job's result, drawn in the top view; and a
//               live slam job's page while frames are posted: its figures, the trajectory and the
//               map growing, finished from the page
//   first_hour  a new user's first hour on a fresh data folder: the first-run panel, the sample
//               data, a calibration, a rig, a SLAM run and its viewer, and the bad inputs a new
//               user meets (a wrong rig, a non-image, a skipped file, each type's example
//               parameters, a failed job with Retry), checking the words the page shows
//   auth        a server with --token: the page asks for the token, then uploads and shows images
// Exit codes: 0 passed, 1 failed, 77 skipped (ctest SKIP_RETURN_CODE) with the reason printed,
// e.g. when the server does not know a job type yet. Screenshots go to --out.
// --url runs against an already running server instead of starting one (for development).

import { spawn, spawnSync } from 'node:child_process';
import crypto from 'node:crypto';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const HERE = path.dirname(fileURLToPath(import.meta.url));
const SOURCE_DIR = process.env.OMNIRIG_SOURCE_DIR || path.resolve(HERE, '../..');
const WEB_DIR = path.join(SOURCE_DIR, 'web');
const REAL_DATA = path.resolve(SOURCE_DIR, '../shared/data/real');
const CHROMIUM = process.env.OMNIRIG_CHROMIUM || '/usr/bin/chromium';
const SKIP = 77;
const JOB_TIMEOUT_MS = 120000;
const FIRST_HOUR_JOB_MS = 300000;  // the first hour's jobs run at sample size on a busy machine

class Skip extends Error {}

function parseArgs(argv) {
  const args = { step: '', omnirig: '', out: '', url: '' };
  for (let i = 0; i < argv.length; i += 1) {
    const key = argv[i].replace(/^--/, '');
    if (!(key in args)) throw new Error(`unknown argument ${argv[i]}`);
    args[key] = argv[++i];
  }
  if (!args.step) throw new Error('--step is required');
  if (!args.url && !args.omnirig) throw new Error('--omnirig (or --url) is required');
  args.out = args.out || path.join(process.env.OMNIRIG_BINARY_DIR || os.tmpdir(), 'test-output', 'browser');
  return args;
}

const T0 = Date.now();
const log = (...parts) => console.log(`[browser/${ARGS.step} ${((Date.now() - T0) / 1000).toFixed(1)} s]`, ...parts);
const ARGS = parseArgs(process.argv.slice(2));
const TEMP = fs.mkdtempSync(path.join(os.tmpdir(), 'omnirig-browser-'));

// ---- the server ---------------------------------------------------------------------------------

async function startServer(extraArgs = []) {
  if (ARGS.url) return { url: ARGS.url.replace(/\/$/, ''), stop: async () => {} };
  const dataDir = path.join(TEMP, 'data');
  fs.mkdirSync(dataDir);
  // --web: the page of this source tree (the binary's default is the tree it was built from).
  const child = spawn(ARGS.omnirig, ['serve', '--host', '127.0.0.1', '--port', '0', '--data', dataDir, '--web', WEB_DIR, ...extraArgs],
    { stdio: ['ignore', 'pipe', 'pipe'], env: { ...process.env, OMNIRIG_TOKEN: '' } });
  const output = [];
  const url = await new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error(`server did not announce its address:\n${output.join('')}`)), 20000);
    const onData = (chunk) => {
      output.push(chunk.toString());
      const match = output.join('').match(/http:\/\/127\.0\.0\.1:(\d+)/);
      if (match && Number(match[1]) > 0) {
        clearTimeout(timer);
        resolve(`http://127.0.0.1:${match[1]}`);
      }
    };
    child.stdout.on('data', onData);
    child.stderr.on('data', onData);
    child.on('exit', (code) => reject(new Error(`server exited with ${code}:\n${output.join('')}`)));
  });
  child.stdout.removeAllListeners('data');
  child.stderr.removeAllListeners('data');
  child.stdout.on('data', (c) => fs.appendFileSync(path.join(TEMP, 'server.log'), c));
  child.stderr.on('data', (c) => fs.appendFileSync(path.join(TEMP, 'server.log'), c));
  await waitFor(async () => [200, 401].includes((await fetch(`${url}/api/v1/health`)).status), 10000, 'the server health check');
  log('server at', url);
  return {
    url,
    stop: () => new Promise((resolve) => {
      child.removeAllListeners('exit');
      child.on('exit', resolve);
      child.kill('SIGTERM');
      setTimeout(() => child.kill('SIGKILL'), 5000).unref();
    }),
  };
}

async function waitFor(predicate, timeoutMs, what) {
  const deadline = Date.now() + timeoutMs;
  let lastError = null;
  while (Date.now() < deadline) {
    try {
      const value = await predicate();
      if (value) return value;
    } catch (e) {
      lastError = e;
    }
    await new Promise((r) => setTimeout(r, 100));
  }
  throw new Error(`timed out waiting for ${what}${lastError ? ` (${lastError.message})` : ''}`);
}

// ---- test data ----------------------------------------------------------------------------------

// Small renders keep the browser tests short: 640x480, 2x2 supersampling, few views; a
// sequence of 10 frames 0.15 m apart (the default spacing of the 40-frame preset).
const SYNTH_ARGS = {
  'mono-calib': ['--views', '6'],
  'stereo-board': ['--views', '8'],
  'stereo-sequence': ['--frames', '10', '--path-length', '1.5'],
};

// A synthetic set from `omnirig synth --preset PRESET`, or null when synth is not available.
function synth(preset) {
  if (ARGS.url && !ARGS.omnirig) return null;
  const out = path.join(TEMP, preset);
  const args = ['synth', '--preset', preset, '--out', out, '--width', '640', '--height', '480', '--supersampling', '2', ...SYNTH_ARGS[preset]];
  const started = Date.now();
  const run = spawnSync(ARGS.omnirig, args, { encoding: 'utf8', timeout: 120000 });
  if (run.status !== 0) {
    log(`omnirig synth --preset ${preset} is not available (${(run.stderr || run.error || '').toString().trim()})`);
    return null;
  }
  log(`omnirig ${args.slice(1).join(' ')}: ${Date.now() - started} ms`);
  const groundTruth = path.join(out, 'ground_truth.json');
  return { dir: out, groundTruth: fs.existsSync(groundTruth) ? JSON.parse(fs.readFileSync(groundTruth, 'utf8')) : null };
}

// Copies files into a fresh folder under their new names: {newName: sourcePath} (copies, not
// links: playwright's folder upload skips symbolic links).
function copySet(name, files) {
  const dir = path.join(TEMP, name);
  for (const [to, from] of Object.entries(files)) {
    fs.mkdirSync(path.dirname(path.join(dir, to)), { recursive: true });
    fs.copyFileSync(from, path.join(dir, to));
  }
  return dir;
}

function imagesIn(dir) {
  const out = [];
  const walk = (d, prefix) => {
    for (const entry of fs.readdirSync(d, { withFileTypes: true })) {
      const rel = prefix ? `${prefix}/${entry.name}` : entry.name;
      const full = path.join(d, entry.name);
      if (entry.isDirectory()) walk(full, rel);
      else if (/\.(png|jpe?g)$/i.test(entry.name)) out.push(rel);
    }
  };
  walk(dir, '');
  return out;
}

// Board spec of a synthetic set from its ground truth, with the documented fallbacks.
// (api/synth_json.h: "board": {"cols", "rows" (inner corners), "square_size_m", ...}).
function boardOf(groundTruth, fallback) {
  const b = groundTruth && groundTruth.board;
  if (!b || !b.cols || !b.rows) return fallback;
  const squareMm = b.square_size_m !== undefined ? b.square_size_m * 1000 : b.square_size_mm;
  return { cols: b.cols, rows: b.rows, square_size_mm: Number((squareMm ?? fallback.square_size_mm).toFixed(6)) };
}

// A mono calibration set: synthetic when synth exists, else the real VMR catadioptric images.
function calibrationSet() {
  const s = synth('mono-calib');
  if (s) return { dir: s.dir, board: boardOf(s.groundTruth, { cols: 8, rows: 6, square_size_mm: 40 }), source: 'omnirig synth --preset mono-calib', maxRmsPx: 0.5 };
  const vmr = path.join(REAL_DATA, 'ocamcalib-vmr');
  if (!fs.existsSync(vmr)) throw new Skip(`neither omnirig synth nor ${vmr} is available`);
  const files = {};
  for (const f of fs.readdirSync(vmr).filter((n) => /\.jpg$/i.test(n)).sort()) files[f] = path.join(vmr, f);
  return { dir: copySet('vmr', files), board: { cols: 6, rows: 7, square_size_mm: 30 }, source: 'real ocamcalib-vmr images', maxRmsPx: 2.0 };
}

// A stereo board set with cam0/ and cam1/: synthetic, else the real fisheye pairs (left -> cam0).
// At most `maxPairs` pairs, so that the jobs on it stay short.
function stereoSet(maxPairs = 12) {
  const s = synth('stereo-board');
  const files = {};
  if (s) {
    const names = fs.readdirSync(path.join(s.dir, 'cam0')).filter((n) => fs.existsSync(path.join(s.dir, 'cam1', n))).sort();
    for (const name of names.slice(0, maxPairs)) {
      for (const cam of ['cam0', 'cam1']) files[`${cam}/${name}`] = path.join(s.dir, cam, name);
    }
    return { dir: copySet('synth-stereo', files), board: boardOf(s.groundTruth, { cols: 8, rows: 6, square_size_mm: 40 }),
      source: `omnirig synth --preset stereo-board (${Math.min(maxPairs, names.length)} pairs)`, groundTruth: s.groundTruth };
  }
  const pairs = path.join(REAL_DATA, 'fisheye-stereo-pairs');
  if (!fs.existsSync(pairs)) throw new Skip(`neither omnirig synth nor ${pairs} is available`);
  for (let i = 1; i <= maxPairs; i += 1) {
    const name = `${String(i).padStart(3, '0')}.jpg`;
    files[`cam0/${name}`] = path.join(pairs, `left${i}.jpg`);
    files[`cam1/${name}`] = path.join(pairs, `right${i}.jpg`);
  }
  return { dir: copySet('fisheye', files), board: { cols: 9, rows: 6, square_size_mm: 24.23 }, source: `real fisheye-stereo-pairs (${maxPairs} pairs)` };
}

// ---- the browser --------------------------------------------------------------------------------

async function launchBrowser() {
  const { chromium } = await import(path.join(WEB_DIR, 'node_modules/playwright-core/index.mjs'));
  const userDataDir = path.join(TEMP, 'chromium-profile');
  const context = await chromium.launchPersistentContext(userDataDir, {
    executablePath: CHROMIUM,
    headless: true,
    viewport: { width: WIDTHS[0], height: 900 },
    acceptDownloads: true,
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync'],
  });
  const page = context.pages()[0] || await context.newPage();
  page.pageErrors = [];
  page.on('pageerror', (e) => page.pageErrors.push(e.message));
  page.on('console', (m) => {
    if (m.type() === 'error' && !m.text().startsWith('Failed to load resource')) log('console error:', m.text());
  });
  page.on('response', (r) => {
    if (r.status() >= 400) log(`HTTP ${r.status()} ${r.request().method()} ${r.url().replace(/^https?:\/\/[^/]+/, '')}`);
  });
  page.setDefaultTimeout(30000);
  return { context, page };
}

async function screenshot(page, name, fullPage = true) {
  fs.mkdirSync(ARGS.out, { recursive: true });
  const file = path.join(ARGS.out, `${name}.png`);
  await page.screenshot({ path: file, fullPage });
  log('screenshot', file);
}

function check(condition, message) {
  if (!condition) throw new Error(`check failed: ${message}`);
}

// The one-click download links under `selector`: each must name an artifact of the job and
// answer 200 with a non-empty body. Returns the artifact names.
async function checkDownloads(page, server, jobId, selector, expected) {
  const links = await page.$$eval(`${selector} a.download`, (as) => as.map((a) => ({
    artifact: a.dataset.artifact, href: a.href, download: a.getAttribute('download'), text: a.textContent })));
  const names = links.map((l) => l.artifact);
  for (const name of expected) check(names.includes(name), `a download link for ${name} under ${selector} (${names.join(', ')})`);
  for (const link of links) {
    check(link.download && link.href.endsWith(`/jobs/${encodeURIComponent(jobId)}/artifacts/${link.artifact.split('/').map(encodeURIComponent).join('/')}`),
      `the link "${link.text}" downloads the artifact ${link.artifact} (${link.href})`);
    const response = await fetch(link.href);
    const body = await response.arrayBuffer();
    check(response.status === 200 && body.byteLength > 0, `${link.artifact} answers 200 with a body (HTTP ${response.status}, ${body.byteLength} bytes)`);
  }
  return names;
}

// Waits until the <img> elements matched by `selector` have loaded (decoded, non-zero size).
async function imagesLoaded(page, selector, what) {
  await page.waitForFunction((sel) => {
    const images = [...document.querySelectorAll(sel)];
    return images.length > 0 && images.every((i) => i.complete && i.naturalWidth > 0);
  }, selector).catch(() => check(false, `${what} loaded (${selector})`));
  return page.$$eval(selector, (images) => images.map((i) => [i.naturalWidth, i.naturalHeight]));
}

// ---- what a user sees at a glance ----------------------------------------------------------------

// The page is read at these widths: a laptop, and a narrow window (half a screen, a tablet).
const WIDTHS = [1280, 800];

// Runs `fn(width)` at each width with the page scrolled to `selector`, taking a screenshot
// `name-WIDTH` of the window (what a person sees there) each time; the page does not overflow
// the window sideways.
async function atWidths(page, name, selector, fn) {
  const results = [];
  for (const width of WIDTHS) {
    await page.setViewportSize({ width, height: 900 });
    if (selector) await page.$eval(selector, (n) => n.scrollIntoView());
    const overflow = await page.evaluate(() => document.documentElement.scrollWidth - window.innerWidth);
    check(overflow <= 0, `at ${width} px the page fits the window's width (${overflow} px too wide)`);
    results.push(await fn(width));
    if (selector) await page.$eval(selector, (n) => n.scrollIntoView());
    await screenshot(page, `${name}-${width}`, false);
  }
  await page.setViewportSize({ width: WIDTHS[0], height: 900 });
  return results;
}

const FULL_ID = /\b[0-9a-f]{16}\b/;

// The text under `selector` names things and shows no 16-digit id.
async function checkNoIds(page, selector, what) {
  const text = await page.$eval(selector, (n) => n.innerText || n.textContent);
  const id = FULL_ID.exec(text);
  check(!id, `${what} shows names, not ids (found ${id && id[0]} in "${text.replace(/\s+/g, ' ').slice(0, 200)}")`);
  return text;
}

// Every value image under `scope` (figure.value-image) carries its colour bar: a continuous one
// with its unit and a finite range, or a key of its categories. Returns the bars' descriptions.
async function checkColourBars(page, scope, expected) {
  await page.waitForFunction(({ sel, n }) => {
    const figures = [...document.querySelectorAll(`${sel} figure.value-image`)];
    return figures.length >= n && figures.every((f) => f.querySelector('.colour-bar'));
  }, { sel: scope, n: expected }, { timeout: 60000 }).catch(() => check(false, `${expected} value image(s) under ${scope} with colour bars`));
  const bars = await page.$$eval(`${scope} figure.value-image .colour-bar`, (list) => list.map((b) => ({
    unit: b.dataset.unit, min: Number(b.dataset.min), max: Number(b.dataset.max), caption: b.querySelector('figcaption')?.textContent || '',
    drawn: b.querySelector('canvas') ? b.querySelector('canvas').width : b.querySelectorAll('li').length,
    visible: b.getBoundingClientRect().width > 0 })));
  for (const bar of bars) {
    check(bar.visible && bar.drawn > 0, `the colour bar "${bar.caption}" is drawn`);
    if (bar.unit === 'category') continue;
    check(bar.unit && Number.isFinite(bar.min) && Number.isFinite(bar.max) && bar.max > bar.min,
      `the colour bar "${bar.caption}" has a unit and a scale (${bar.unit}, ${bar.min} to ${bar.max})`);
    check(bar.caption.includes(bar.unit), `the colour bar's caption states its unit (${bar.caption})`);
  }
  return bars.map((b) => (b.unit === 'category' ? b.caption : `${b.caption}: ${b.min.toPrecision(3)} to ${b.max.toPrecision(3)}`));
}

// The job page's "Download all as zip": the browser's download is a zip that unzip tests whole,
// holding exactly the job's artifacts, each with its recorded SHA-256. Kept in the output folder.
async function checkZipDownload(page, server, jobId) {
  const link = await page.waitForSelector('#download-zip');
  const [download] = await Promise.all([page.waitForEvent('download'), link.click()]);
  fs.mkdirSync(ARGS.out, { recursive: true });
  const file = path.join(ARGS.out, download.suggestedFilename());
  await download.saveAs(file);
  const tested = spawnSync('unzip', ['-t', file], { encoding: 'utf8' });
  check(tested.status === 0 && /No errors detected/.test(tested.stdout), `unzip -t passes on ${file} (${tested.stdout}${tested.stderr})`);
  const listed = spawnSync('unzip', ['-Z1', file], { encoding: 'utf8' }).stdout.split('\n').filter(Boolean).sort();
  const artifacts = await (await fetch(`${server.url}/api/v1/jobs/${jobId}/artifacts`)).json();
  check(JSON.stringify(listed) === JSON.stringify(artifacts.map((a) => a.name).sort()),
    `the zip holds the job's artifacts (${listed.join(', ')})`);
  for (const a of artifacts) {
    const bytes = spawnSync('unzip', ['-p', file, a.name], { maxBuffer: 1 << 30 }).stdout;
    check(crypto.createHash('sha256').update(bytes).digest('hex') === a.sha256, `${a.name} in the zip has its recorded SHA-256`);
  }
  log(`zip download: ${path.basename(file)}, ${listed.length} entries, ${fs.statSync(file).size} bytes, checked`);
  return `the zip (${listed.length} artifacts) downloads whole`;
}

// ---- steps --------------------------------------------------------------------------------------

// Creates a dataset from the page and uploads `dir` with the folder picker; returns its id.
async function uploadDataset(page, server, name, dir) {
  await page.goto(`${server.url}/#/datasets`);
  await page.fill('input[name=name]', name);
  await page.click('button:has-text("Create dataset")');
  await page.waitForURL(/#\/datasets\/.+/);
  const id = decodeURIComponent(page.url().split('#/datasets/')[1]);
  const expected = imagesIn(dir).length;
  const started = Date.now();
  await page.setInputFiles('input[name=folder]', dir);
  await page.waitForSelector('#upload-finished', { timeout: 60000 });
  const finished = await page.textContent('#upload-finished');
  check(/Upload finished\.$/.test(finished.trim()), `upload finished cleanly (${finished})`);
  await page.waitForFunction((n) => document.querySelector('#image-count')?.textContent === String(n), expected);
  log(`uploaded ${expected} images into dataset ${id} in ${Date.now() - started} ms`);
  return { id, count: expected };
}

// Uploads one more file to the dataset page that is open; returns null when stored, else the
// error the page shows.
async function uploadOneMore(page, file) {
  const before = await page.$$eval('.upload-row', (r) => r.length);
  await page.setInputFiles('input[name=files]', file);
  const row = await page.waitForSelector(`.upload-row:nth-child(${before + 1}).done, .upload-row:nth-child(${before + 1}).failed`);
  return (await row.evaluate((r) => r.classList.contains('failed'))) ? (await row.textContent()).trim() : null;
}

// Submits a job from the Jobs page form; returns the job id, or throws Skip when the server
// does not know the job type.
async function submitJob(page, server, datasetId, type, fill) {
  await page.goto(`${server.url}/#/jobs?dataset=${encodeURIComponent(datasetId)}`);
  await page.waitForSelector('#job-form');
  await page.selectOption('#job-form select[name=type]', type);
  await page.selectOption('#job-form select[name=dataset]', datasetId);
  if (fill) await fill(page);
  await page.click('#job-form button[type=submit]');
  const outcome = await page.waitForSelector('#job-form .notice a, #job-form .error');
  const text = await outcome.textContent();
  if (await outcome.evaluate((n) => n.closest('.error') !== null)) {
    const message = await page.textContent('#job-form .error');
    if (/unknown|not (a )?known|unsupported|no such/i.test(message) && message.includes(type)) {
      throw new Skip(`the server does not run "${type}" jobs yet: ${message.trim()}`);
    }
    throw new Error(`the server refused the ${type} job: ${message.trim()}`);
  }
  const id = await outcome.getAttribute('data-job-id');
  check(id && text.includes(id.slice(0, 8)), `the notice names the job by what it runs on, with its short id (${text})`);
  check(!text.includes(id), `the notice shows no full id (${text})`);
  log(`submitted ${type} job ${id}: "${text.trim()}"`);
  return id;
}

async function fillBoard(page, board) {
  await page.fill('#job-form input[name=cols]', String(board.cols));
  await page.fill('#job-form input[name=rows]', String(board.rows));
  await page.fill('#job-form input[name=square_size_mm]', String(board.square_size_mm));
}

// Opens the job's page and follows it to a terminal state; checks that the progress bar moved
// monotonically and reached 100 %. Returns the final state.
async function followJob(page, server, jobId, screenshotName, timeoutMs = JOB_TIMEOUT_MS) {
  await page.goto(`${server.url}/#/jobs/${encodeURIComponent(jobId)}`);
  await page.waitForSelector('#job-status');
  const seen = [];
  const deadline = Date.now() + timeoutMs;
  let state = '';
  let shotRunning = false;
  for (;;) {
    const status = await page.$eval('#job-status', (n) => ({
      state: n.dataset.state, percent: Number(n.querySelector('[role=progressbar]')?.getAttribute('aria-valuenow')),
      stage: n.querySelector('.grow > div:nth-child(3)')?.textContent || '' }));
    state = status.state;
    if (!seen.length || seen[seen.length - 1].percent !== status.percent || seen[seen.length - 1].state !== state) seen.push(status);
    if (state === 'running' && !shotRunning && screenshotName) {
      await screenshot(page, `${screenshotName}-running`);
      shotRunning = true;
    }
    if (['succeeded', 'failed', 'canceled', 'cancelled'].includes(state)) break;
    check(Date.now() < deadline, `job ${jobId} finished within ${timeoutMs / 1000} s (last: ${JSON.stringify(status)})`);
    await page.waitForTimeout(150);
  }
  log(`job ${jobId} progress seen:`, seen.map((s) => `${s.state} ${s.percent}%${s.stage ? ` (${s.stage.trim().slice(0, 40)})` : ''}`).join(' -> '));
  if (state === 'failed') {
    const why = await page.textContent('#job-error').catch(() => '');
    if (screenshotName) await screenshot(page, `${screenshotName}-failed`);
    throw new Error(`job ${jobId} failed: ${why}`);
  }
  check(state === 'succeeded', `job ${jobId} succeeded (state ${state})`);
  const doneEarly = seen.find((s) => s.state === 'running' && /^\s*done\b/.test(s.stage));
  check(!doneEarly, `the stage never says "done" while the job runs (${JSON.stringify(doneEarly)})`);
  const percents = seen.map((s) => s.percent);
  check(percents.every((p, i) => i === 0 || p >= percents[i - 1]), `progress never went back (${percents.join(', ')})`);
  check(percents[percents.length - 1] === 100, 'the progress bar reached 100 %');
  return state;
}

async function stepDatasets(page, server) {
  const s = calibrationSet();
  // A folder with cam0/ and cam1/ and a stray non-image, to check names, skipping and errors.
  const files = {};
  const images = imagesIn(s.dir).slice(0, 4);
  images.forEach((f, i) => { files[`cam${i % 2}/${path.basename(f)}`] = path.join(s.dir, f); });
  const dir = copySet('mixed', files);
  const { id, count } = await uploadDataset(page, server, 'browser-datasets', dir);
  const listing = await (await fetch(`${server.url}/api/v1/datasets/${id}`)).json();
  const names = listing.images.map((i) => i.name).sort();
  check(JSON.stringify(names) === JSON.stringify(Object.keys(files).sort()), `server names keep cam0/ and cam1/ (${names})`);
  await page.waitForFunction((n) => [...document.querySelectorAll('.thumbs img')].filter((i) => i.complete && i.naturalWidth > 0).length === n, count);
  await screenshot(page, 'datasets-uploaded');

  // Resume: sending the same folder again uploads nothing and says so.
  const rowsBefore = await page.$$eval('.upload-row', (r) => r.length);
  await page.setInputFiles('input[name=folder]', dir);
  await page.waitForSelector(`.notice:has-text("${count} already on the server")`);
  check(await page.$$eval('.upload-row', (r) => r.length) === rowsBefore, 'a resumed upload sends nothing already on the server');

  // Drag and drop of a file on the drop zone (a synthetic drop: playwright cannot drag from the desktop).
  const extra = imagesIn(s.dir)[4];
  await page.evaluate(async ({ name, b64 }) => {
    const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
    const transfer = new DataTransfer();
    transfer.items.add(new File([bytes], name, { type: 'image/jpeg' }));
    const zone = document.querySelector('#dropzone');
    for (const type of ['dragover', 'drop']) zone.dispatchEvent(new DragEvent(type, { dataTransfer: transfer, bubbles: true, cancelable: true }));
  }, { name: path.basename(extra), b64: fs.readFileSync(path.join(s.dir, extra)).toString('base64') });
  await page.waitForSelector(`.upload-row.done[data-name="${path.basename(extra)}"]`);
  await page.waitForFunction((n) => document.querySelector('#image-count')?.textContent === String(n), count + 1);

  // An image uploaded by mistake goes again with its Remove button (its camera folder kept in the name).
  const mistake = names.find((n) => n.startsWith('cam1/'));
  page.once('dialog', (dialog) => dialog.accept());
  await page.click(`.thumb button.remove-image[data-name="${mistake}"]`);
  await page.waitForFunction((n) => document.querySelector('#image-count')?.textContent === String(n), count);
  const afterRemoval = (await (await fetch(`${server.url}/api/v1/datasets/${id}/images`)).json()).map((i) => i.name);
  check(!afterRemoval.includes(mistake) && afterRemoval.length === count, `${mistake} was removed (${afterRemoval.length} files left)`);

  // A file that is not an image, named like one: the server refuses it, the page shows its message.
  const fake = path.join(TEMP, 'fake', 'not-an-image.png');
  fs.mkdirSync(path.dirname(fake), { recursive: true });
  fs.writeFileSync(fake, 'this is text, not a PNG');
  await page.setInputFiles('input[name=files]', fake);
  const errorText = await (await page.waitForSelector('.upload-row.failed .error')).textContent();
  log('non-image upload refused with:', errorText.trim());
  // The page shows the server's JSON message, not a bare status line.
  check(!/HTTP \d{3}/.test(errorText), `the error shows the server's message (${errorText})`);
  const video = await videoResumes(page, server, id);
  await page.goto(`${server.url}/#/datasets`);
  await page.waitForSelector(`tr[data-dataset-id="${id}"]`);
  await screenshot(page, 'datasets-list');
  const errors = await jobErrors(page, server, id);
  return `uploaded ${count} images (${s.source}), resume skipped all, one dropped, ${mistake} removed, ` +
    `non-image refused: ${errorText.trim()}; ${video}; ${errors}`;
}

// A video larger than one chunk (16 MiB), whose first chunk an earlier session sent: the page
// asks the server, sends only the rest (one PUT with its Content-Range), and the dataset lists
// it as a video. The MP4's boxes are whole; its content is noise (the upload decodes nothing).
async function videoResumes(page, server, datasetId) {
  const chunk = 16 << 20;
  const payload = Buffer.alloc(chunk + (3 << 20));
  for (let i = 0; i < payload.length; i += 4) payload.writeUInt32LE((i * 2654435761) >>> 0, i);
  const box = (type, content) => {
    const head = Buffer.alloc(8);
    head.writeUInt32BE(8 + content.length, 0);
    head.write(type, 4, 'latin1');
    return Buffer.concat([head, content]);
  };
  const mp4 = Buffer.concat([box('ftyp', Buffer.from('isom\0\0\0\0', 'latin1')), box('mdat', payload),
    box('moov', Buffer.alloc(64, 109))]);
  const file = path.join(TEMP, 'video', 'cam0.mp4');
  fs.mkdirSync(path.dirname(file), { recursive: true });
  fs.writeFileSync(file, mp4);
  const url = `${server.url}/api/v1/datasets/${datasetId}/images/cam0.mp4`;
  const first = await fetch(url, { method: 'PUT', body: mp4.subarray(0, chunk),
    headers: { 'Content-Range': `bytes 0-${chunk - 1}/${mp4.length}` } });
  check(first.status === 202, `the first chunk is taken (${first.status})`);
  const ranges = [];
  const onRequest = (request) => {
    if (request.method() === 'PUT' && request.url().endsWith('/cam0.mp4')) ranges.push(request.headers()['content-range']);
  };
  page.on('request', onRequest);
  const refused = await uploadOneMore(page, file);
  page.off('request', onRequest);
  check(refused === null, `the video is stored (${refused})`);
  check(ranges.length === 1 && ranges[0] === `bytes ${chunk}-${mp4.length - 1}/${mp4.length}`,
    `the page resumed at the server's offset (${ranges.join(', ')})`);
  const listing = await (await fetch(`${server.url}/api/v1/datasets/${datasetId}`)).json();
  const stored = listing.images.find((i) => i.name === 'cam0.mp4');
  check(stored && stored.size === mp4.length && stored.content_type === 'video/mp4', `the whole video is listed (${JSON.stringify(stored)})`);
  check(listing.video_count === 1, `video_count counts it (${listing.video_count})`);
  await page.waitForFunction(() => document.querySelector('#videos')?.textContent === 'cam0.mp4');
  return `a ${(mp4.length / (1 << 20)).toFixed(1)} MiB video resumed at ${chunk} bytes`;
}

// Errors on the Jobs page: a refused submission shows the server's message naming the field, and
// a job that fails (relative_pose on images without partners) shows why on its page.
async function jobErrors(page, server, datasetId) {
  await page.goto(`${server.url}/#/jobs?dataset=${encodeURIComponent(datasetId)}`);
  await page.waitForSelector('#job-form');
  await page.fill('#job-form textarea[name=extra]', '{"bogus_field": 1}');
  await page.click('#job-form button[type=submit]');
  const refused = (await (await page.waitForSelector('#job-form .error')).textContent()).trim();
  log('refused submission:', refused);
  check(refused.includes('bogus_field'), `the refusal names the unknown field (${refused})`);
  await page.fill('#job-form textarea[name=extra]', '');
  let failed;
  try {
    const jobId = await submitJob(page, server, datasetId, 'relative_pose', (p) => fillBoard(p, { cols: 6, rows: 7, square_size_mm: 30 }));
    await followJob(page, server, jobId, null).then(() => check(false, 'relative_pose on unpaired images fails'), (e) => {
      if (!/failed: /.test(e.message)) throw e;
    });
    failed = (await page.textContent('#job-error')).trim();
    log('failed job shows:', failed);
    check(failed.length > 20, 'the failed job explains why');
    await screenshot(page, 'job-failed');
  } catch (e) {
    if (!(e instanceof Skip)) throw e;
    failed = `not checked (${e.message})`;
  }
  return `refused job: "${refused}"; failed job: "${failed}"`;
}

async function stepCalibration(page, server) {
  const s = calibrationSet();
  log('calibration data:', s.source, JSON.stringify(s.board));
  const { id } = await uploadDataset(page, server, 'browser-calibration', s.dir);
  const jobId = await submitJob(page, server, id, 'calibration', (p) => fillBoard(p, s.board));
  const second = await cancelFromList(page, jobId);
  await followJob(page, server, jobId, 'calibration');
  await page.waitForSelector('#calibration-report');
  const rms = Number((await page.textContent('#rms')).replace(/[^0-9.eE+-]/g, ''));
  const intrinsics = await page.$$eval('#intrinsics tbody tr', (rows) => rows.map((r) => r.dataset.name));
  const used = await page.$$eval('#image-overlays figure[data-used=true]', (f) => f.length);
  log(`report: RMS ${rms} px, intrinsics ${intrinsics.join(' ')}, ${used} images used`);
  check(Number.isFinite(rms) && rms > 0 && rms < s.maxRmsPx, `RMS ${rms} px is under ${s.maxRmsPx} px`);
  for (const name of ['xi', 'gamma_u', 'gamma_v', 'u0', 'v0']) check(intrinsics.includes(name), `intrinsic ${name} shown`);
  check(used >= 3, 'at least three images used');
  const chartInk = await page.$eval('#error-chart', (c) => {
    const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
    let n = 0;
    for (let i = 0; i < d.length; i += 4) if (d[i + 3] > 0 && d[i + 2] > 200 && d[i] < 120) n += 1;  // blue bars
    return n;
  });
  check(chartInk > 100, `the per-image error chart has bars (${chartInk} blue pixels)`);
  await page.waitForFunction(() => [...document.querySelectorAll('#image-overlays img')].slice(0, 4).every((i) => i.complete && i.naturalWidth > 0));
  await page.waitForSelector('#artifacts tr[data-artifact]');
  await screenshot(page, 'calibration-report');
  const coverage = await checkCoverage(page, server, jobId);
  await checkNoIds(page, '#job-title', 'the job\'s title');
  const bars = await atWidths(page, 'calibration-colour-bars', '#coverage', () => checkColourBars(page, '#coverage', 1));
  const zipped = await checkZipDownload(page, server, jobId);
  const hinted = await rerunWithHint(page, server, jobId, s.board);
  const retried = await retryAndDelete(page, server, second);
  const advised = await checkAdvice(page, server, s);
  return `calibration job on ${s.source}: RMS ${rms} px, ${used} images used; ${coverage}; colour bars ${bars[0].join(' | ')}; ${zipped}; ` +
    `${advised}; ${hinted}; ${retried}`;
}

// Advice in words: a calibration from only three of the views leaves sectors of the mirror disk
// without a board; the page lists the result's advice, sentence by sentence.
async function checkAdvice(page, server, s) {
  const files = {};
  for (const f of imagesIn(s.dir).sort().slice(0, 3)) files[f] = path.join(s.dir, f);
  const { id } = await uploadDataset(page, server, 'browser-calibration-3-views', copySet('three-views', files));
  const jobId = await submitJob(page, server, id, 'calibration', (p) => fillBoard(p, s.board));
  await followJob(page, server, jobId, null);
  await page.waitForSelector('#coverage');
  const result = await (await fetch(`${server.url}/api/v1/jobs/${jobId}/result`)).json();
  const given = result.coverage.advice || [];
  check(given.length > 0, `three views leave part of the disk uncovered: the result gives advice (${JSON.stringify(result.coverage)})`);
  const [shown] = await atWidths(page, 'calibration-advice-low', '#coverage', () => checkAdviceText(page, result.coverage, 'three views'));
  const percent = (await page.textContent('#coverage-percent')).trim();
  check(percent.startsWith(`${Math.round(100 * result.coverage.covered_fraction)} %`), `the three-view coverage is shown (${percent})`);
  log(`three views: "${percent}"; advice: ${shown.join(' | ')}`);
  return `three views: "${percent}", advice shown: "${shown[0]}"${shown.length > 1 ? ` and ${shown.length - 1} more` : ''}`;
}

// The advice a person reads under the coverage: the result's sentences, each shown; while part
// of the disk has no corner (coverage under 80 %), the regions named by ring and clock hours; the
// board poses stated. Returns the lines shown.
const REGION_WORDS = /^no corner in the (inner|middle|outer) ring( \(near the rim\))?, (all around|([1-9]|1[0-2]) to ([1-9]|1[0-2]) o'clock): add views with the board there$/;
async function checkAdviceText(page, coverage, what) {
  const given = coverage.advice || [];
  const shown = await page.$$eval('#coverage-advice li', (items) => items.map((i) => i.textContent.trim()));
  check(shown.length === given.length && given.every((a, i) => shown[i].startsWith(a)),
    `${what}: the page lists the advice (${shown.length} shown of ${given.length})`);
  const regions = shown.filter((a) => REGION_WORDS.test(a));
  check(regions.length === (coverage.uncovered_regions || []).length,
    `${what}: each region without a corner is named by ring and clock (${regions.length} of ${(coverage.uncovered_regions || []).length}: ${shown.join(' | ')})`);
  if (coverage.covered_fraction < 0.8) {
    check(regions.length > 0, `${what}: at ${Math.round(100 * coverage.covered_fraction)} % coverage the advice names the regions without a corner (${shown.join(' | ')})`);
  }
  if (!coverage.uncertainty_flat) {
    for (const pose of coverage.missing_poses || []) {
      check(shown.some((a) => a.startsWith(`no ${pose} board`)), `${what}: the advice names the missing ${pose} board (${shown.join(' | ')})`);
    }
  }
  const poses = (await page.textContent('#board-poses')).trim();
  check(/^tilted up to [0-9]+° from facing the camera; [0-9.]+ to [0-9.]+ m away \(median [0-9.]+ m\)$/.test(poses), `${what}: the board poses in words (${poses})`);
  const visible = await page.$eval('#coverage-advice', (n) => n.getBoundingClientRect().width > 0);
  check(visible, `${what}: the advice is visible`);
  return shown;
}

// The coverage report and the exports as a person reads them: the percentage of the mirror disk
// near a used corner, the largest uncertainty, each piece of advice, both images, the downloads.
async function checkCoverage(page, server, jobId) {
  const result = await (await fetch(`${server.url}/api/v1/jobs/${jobId}/result`)).json();
  const coverage = result.coverage;
  check(coverage && Number.isFinite(coverage.covered_fraction), `the result has a coverage report (${JSON.stringify(coverage)})`);
  const percentText = (await page.textContent('#coverage-percent')).trim();
  const expected = `${Math.round(100 * coverage.covered_fraction)} % of the mirror disk within ${Math.round(coverage.near_px)} px of a used corner`;
  check(percentText === expected, `the page says "${expected}" (shows "${percentText}")`);
  const uncertaintyText = (await page.textContent('#max-uncertainty')).trim();
  if (Number.isFinite(coverage.max_uncertainty_px)) {
    const shown = Number((uncertaintyText.match(/at most ([0-9.eE+-]+) px/) || [])[1]);
    // Shown with two significant digits: off by at most half a unit of the second digit.
    const halfUnit = 0.5 * 10 ** (Math.floor(Math.log10(coverage.max_uncertainty_px)) - 1);
    check(Math.abs(shown - coverage.max_uncertainty_px) <= halfUnit * (1 + 1e-9),
      `the largest uncertainty shown (${uncertaintyText}) is the result's ${coverage.max_uncertainty_px} px`);
  }
  const [advice] = await atWidths(page, 'calibration-advice-middle', '#coverage', () => checkAdviceText(page, coverage, 'every view'));
  const images = ['#coverage-image img', ...(coverage.uncertainty_image ? ['#uncertainty-image img'] : [])];
  for (const selector of images) {
    const [[w, h]] = await imagesLoaded(page, selector, 'the coverage image');
    check(w > 0 && h > 0, `${selector} loaded (${w}x${h})`);
  }
  check(await page.$eval('#coverage-image img', (i) => i.src.endsWith(`/artifacts/${'coverage.png'}`)), 'the coverage image is the coverage.png artifact');
  const exports = result.exports || {};
  const names = await checkDownloads(page, server, jobId, '#export-downloads', [exports.opencv_omnidir, exports.kalibr]);
  check(names.includes('camera_opencv.yaml') && names.includes('camera_kalibr.yaml'), `the exports are camera_opencv.yaml and camera_kalibr.yaml (${names})`);
  await page.$eval('#coverage', (c) => c.scrollIntoView());
  await screenshot(page, 'calibration-coverage');
  log(`coverage: "${percentText}"; ${uncertaintyText}; advice: ${advice.join(' | ') || 'none'}; downloads ${names.join(', ')}`);
  return `coverage "${percentText}", ${advice.length} advice line(s), ${uncertaintyText}, downloads ${names.join(' and ')} answer 200`;
}

// From the Jobs page just after submitting `first`: submits the same job again and cancels it
// with its Cancel button. Returns {id, canceled} (canceled false when it finished first).
async function cancelFromList(page, first) {
  await page.click('#job-form button[type=submit]');
  await page.waitForFunction((f) => {
    const link = document.querySelector('#job-form .notice a');
    return link && link.dataset.jobId !== f;
  }, first);
  const id = await page.getAttribute('#job-form .notice a', 'data-job-id');
  const row = `#job-list tr[data-job-id="${id}"]`;
  await page.waitForSelector(row);
  await screenshot(page, 'jobs-list');
  const cancel = await page.$(`${row} button[data-action=cancel]`);
  if (cancel) await cancel.click().catch(() => {});
  await page.waitForSelector(`${row}[data-state=canceled], ${row}[data-state=succeeded]`, { timeout: JOB_TIMEOUT_MS });
  const state = await page.$eval(row, (r) => r.dataset.state);
  log(state === 'canceled' ? `job ${id} canceled from the list` : `job ${id} finished before Cancel could be clicked`);
  return { id, canceled: state === 'canceled' };
}

// Retries the canceled job from its page (it must then succeed) and deletes it from the list.
async function retryAndDelete(page, server, { id, canceled }) {
  let retried = 'retry not exercised (the job finished before it could be canceled)';
  if (canceled) {
    await page.goto(`${server.url}/#/jobs/${encodeURIComponent(id)}`);
    // Retry offers to edit the parameters first; unchanged, the same job runs again.
    await page.click('#job-status button[data-action=retry]');
    await page.waitForSelector('.retry-editor textarea[name=retry_params]');
    await page.click('.retry-editor button[data-action=retry-run]');
    await page.waitForSelector('#job-status:not([data-state=canceled])');
    await followJob(page, server, id, null);
    retried = `job ${id} canceled, retried to success`;
  }
  await page.goto(`${server.url}/#/jobs`);
  page.once('dialog', (dialog) => dialog.accept());
  await page.click(`#job-list tr[data-job-id="${id}"] button[data-action=delete]`);
  await page.waitForSelector(`#job-list tr[data-job-id="${id}"]`, { state: 'detached' });
  const response = await fetch(`${server.url}/api/v1/jobs/${id}`);
  check(response.status === 404, `a deleted job is gone (HTTP ${response.status})`);
  return `${retried}, then deleted`;
}

// The paper's manual hint: click the four outer corners of one image (where the first run found
// them) on the report page, re-run, and check that the new job used the hint for that image.
async function hintCorners(result, board) {
  const ids = [0, board.cols - 1, board.rows * board.cols - 1, (board.rows - 1) * board.cols];
  for (const image of result.images) {
    if (!image.used || !image.corners_px || !image.corner_ids) continue;
    const byId = new Map(image.corner_ids.map((id, k) => [id, image.corners_px[k]]));
    if (ids.every((id) => byId.has(id))) return { name: image.name, corners: ids.map((id) => byId.get(id)) };
  }
  return null;
}

async function rerunWithHint(page, server, jobId, board) {
  const api = async (p) => (await fetch(`${server.url}/api/v1${p}`)).json();
  const target = await hintCorners(await api(`/jobs/${jobId}/result`), board);
  check(target, 'an image with all four outer corners detected, to hint');
  await page.click(`#image-overlays figure[data-image="${target.name}"] .hint-button`);
  const img = await page.waitForSelector(`.hint-editor[data-image="${target.name}"] img`);
  await page.waitForFunction((i) => i.complete && i.naturalWidth > 0, img);
  await img.scrollIntoViewIfNeeded();
  const box = await img.boundingBox();
  const natural = await img.evaluate((i) => [i.naturalWidth, i.naturalHeight]);
  for (const [u, v] of target.corners) {
    await page.mouse.click(box.x + ((u + 0.5) / natural[0]) * box.width, box.y + ((v + 0.5) / natural[1]) * box.height);
  }
  await screenshot(page, 'calibration-hint');
  await page.click('#hint-rerun');
  await page.waitForURL((url) => url.hash.startsWith('#/jobs/') && !url.hash.includes(jobId));
  const newJob = decodeURIComponent(page.url().split('#/jobs/')[1]);
  await followJob(page, server, newJob, null);
  const job = await api(`/jobs/${newJob}`);
  const hint = job.params && job.params.hints && job.params.hints[target.name];
  check(hint && hint.length === 4, `the new job carries four hinted corners for ${target.name}`);
  // Clicks land on whole CSS pixels: up to one per axis, each (natural / shown width) image pixels.
  const tolerance = Math.SQRT2 * Math.max(1, natural[0] / box.width) + 0.05;
  const worst = Math.max(...hint.map(([u, v], k) => Math.hypot(u - target.corners[k][0], v - target.corners[k][1])));
  check(worst <= tolerance, `the clicks landed on the corners (worst ${worst.toFixed(2)} px, tolerance ${tolerance.toFixed(2)} px)`);
  const image = (await api(`/jobs/${newJob}/result`)).images.find((i) => i.name === target.name);
  log(`hinted re-run ${newJob}: ${target.name} detector "${image.detector}", used ${image.used}, RMS ${image.rms_px}`);
  check(image.used, `the hinted image ${target.name} is used (${image.reason})`);
  if (image.detector !== undefined) check(image.detector === 'hint', `${target.name} was found through the hint (detector "${image.detector}")`);
  return `hint re-run on ${target.name}: clicks within ${worst.toFixed(2)} px, image used with RMS ${Number(image.rms_px).toFixed(3)} px`;
}

async function runRelativePose(page, server, s) {
  const { id } = await uploadDataset(page, server, 'browser-stereo', s.dir);
  const jobId = await submitJob(page, server, id, 'relative_pose', (p) => fillBoard(p, s.board));
  await followJob(page, server, jobId, 'stereo');
  return { datasetId: id, jobId };
}

async function clickAndCheckCurve(page, from, to, fu, fv) {
  const img = await page.waitForSelector(`#epipolar-explorer figure[data-camera=${from}] img`);
  await page.waitForFunction((i) => i.complete && i.naturalWidth > 0, img);
  await img.scrollIntoViewIfNeeded();
  const box = await img.boundingBox();
  await page.mouse.click(box.x + box.width * fu, box.y + box.height * fv);
  await page.waitForSelector(`#epipolar-status[data-from=${from}], #epipolar-explorer .error`);
  const status = await page.$('#epipolar-status');
  check(status, `the epipolar request succeeded (${await page.textContent('#epipolar-explorer').catch(() => '')})`);
  const points = await page.$$eval(`#epipolar-explorer figure[data-camera=${to}] svg polyline.curve`,
    (lines) => lines.map((l) => l.points.numberOfItems));
  return { points, text: (await status.textContent()).trim() };
}

async function stepStereo(page, server) {
  const s = stereoSet(8);
  log('stereo data:', s.source, JSON.stringify(s.board));
  const { datasetId, jobId } = await runRelativePose(page, server, s);
  await page.waitForSelector('#stereo-report');
  const baseline = (await page.textContent('#baseline')).trim();
  const result = await (await fetch(`${server.url}/api/v1/jobs/${jobId}/result`)).json();
  const truth = s.groundTruth && s.groundTruth.rig && s.groundTruth.rig.baseline_m;
  log(`baseline shown: ${baseline}; result ${result.baseline_m} m${truth ? `; ground truth ${truth} m` : ''}`);
  check(baseline.startsWith(`${(result.baseline_m * 1000).toFixed(3)} mm`), 'the page shows the result\'s baseline in mm');
  const rigReport = await checkRigReport(page, server, jobId, result);
  // Click pixels around the image until one has a curve in the other image (a pixel outside the
  // mirror disk has none, and the page says so).
  let found = null;
  for (const [fu, fv] of [[0.3, 0.5], [0.7, 0.4], [0.5, 0.25], [0.5, 0.75], [0.25, 0.3]]) {
    const r = await clickAndCheckCurve(page, 'cam0', 'cam1', fu, fv);
    log(`cam0 click at (${fu}, ${fv}): ${r.text}`);
    if (r.points.some((n) => n > 1)) {
      found = r;
      break;
    }
  }
  check(found, 'a click on cam0 drew an epipolar curve on cam1');
  await screenshot(page, 'stereo-epipolar-cam0-to-cam1');
  const back = await clickAndCheckCurve(page, 'cam1', 'cam0', 0.5, 0.3);
  log(`cam1 click: ${back.text}`);
  check(back.points.some((n) => n > 1), 'a click on cam1 drew an epipolar curve on cam0');
  await screenshot(page, 'stereo-epipolar-cam1-to-cam0');
  const instant = await reconstructAndView(page, server, datasetId, jobId, s.dir);
  return `relative_pose on ${s.source}: baseline ${baseline}; ${rigReport}; cam0 click -> ${found.text}; cam1 click -> ${back.text}; ${instant}`;
}

// The rig report's observations line and its Kalibr camchain download.
async function checkRigReport(page, server, jobId, result) {
  let observations = 'no observations in the result';
  if (result.observations) {
    const o = result.observations;
    observations = (await page.textContent('#observations')).trim();
    check(observations.startsWith(`${o.pairs_used} of ${o.pairs_given} stereo pairs`), `the observations line counts the pairs (${observations})`);
  }
  check(result.exports && result.exports.kalibr_camchain === 'camchain_kalibr.yaml', `the result names camchain_kalibr.yaml (${JSON.stringify(result.exports)})`);
  await checkDownloads(page, server, jobId, '#rig-downloads', ['camchain_kalibr.yaml']);
  log(`rig report: observations "${observations}"; camchain_kalibr.yaml downloads`);
  return `observations "${observations}", camchain_kalibr.yaml downloads`;
}

// Counts canvas pixels that differ from the viewer's background.
async function drawnPixels(page) {
  return page.$eval('#viewer canvas', (canvas) => {
    const copy = document.createElement('canvas');
    copy.width = canvas.width;
    copy.height = canvas.height;
    const ctx = copy.getContext('2d');
    ctx.drawImage(canvas, 0, 0);
    const d = ctx.getImageData(0, 0, copy.width, copy.height).data;
    let n = 0;
    for (let i = 0; i < d.length; i += 4) if (Math.abs(d[i] - 0x0b) + Math.abs(d[i + 1] - 0x0f) + Math.abs(d[i + 2] - 0x17) > 30) n += 1;
    return { n, total: d.length / 4 };
  });
}

// Runs in the page: makes a coloured binary PLY of `count` points on a sphere of radius 2 m
// (deterministic) and gives it to the viewer's file input as if the user had chosen it (made in
// the page, because sending 38 MB through playwright's setInputFiles takes longer than the rest).
function chooseSpherePly(count) {
  const header = new TextEncoder().encode(`ply\nformat binary_little_endian 1.0\ncomment omnirig browser test\n` +
    `element vertex ${count}\nproperty float x\nproperty float y\nproperty float z\n` +
    'property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uint observations\nend_header\n');
  const bytes = new Uint8Array(header.length + count * 19);
  bytes.set(header);
  const view = new DataView(bytes.buffer);
  const golden = Math.PI * (3 - Math.sqrt(5));
  for (let i = 0; i < count; i += 1) {
    const y = 1 - (2 * (i + 0.5)) / count;
    const r = Math.sqrt(1 - y * y);
    const o = header.length + i * 19;
    view.setFloat32(o, 2 * r * Math.cos(golden * i), true);
    view.setFloat32(o + 4, 2 * y, true);
    view.setFloat32(o + 8, 2 * r * Math.sin(golden * i), true);
    bytes[o + 12] = 255;
    bytes[o + 13] = Math.round(127 + 127 * y);
    bytes[o + 14] = 60;
    view.setUint32(o + 15, 2, true);
  }
  const transfer = new DataTransfer();
  transfer.items.add(new File([bytes], 'sphere.ply'));
  const input = document.querySelector('#ply-file');
  input.files = transfer.files;
  input.dispatchEvent(new Event('change', { bubbles: true }));
  return bytes.length;
}

async function stepViewerPly(page, server) {
  const count = 2000000;
  await page.goto(`${server.url}/#/viewer`);
  await page.waitForSelector('#ply-file');
  log('viewer page loaded (three.js included)');
  const started = Date.now();
  const size = await page.evaluate(chooseSpherePly, count);
  log(`a ${(size / 1e6).toFixed(1)} MB PLY of ${count} points made and chosen in ${Date.now() - started} ms`);
  await page.waitForFunction(() => Number(document.querySelector('#viewer')?.dataset.frames || 0) > 0, null, { timeout: 60000 });
  const loadMs = Date.now() - started;
  const hud = await page.innerText('#viewer .hud');
  check(hud.includes(count.toLocaleString('en-US')) || hud.includes('2,000,000') || hud.includes(String(count)), `HUD shows ${count} points (${hud})`);
  const before = await drawnPixels(page);
  log(`2,000,000 points: loaded and drawn in ${loadMs} ms; ${before.n} of ${before.total} pixels drawn`);
  check(before.n > 1000, `points were drawn (${before.n} pixels differ from the background)`);
  // The point size control makes the drawing bigger (a full redraw: its time is the draw time).
  const framesNow = async () => Number(await page.$eval('#viewer', (v) => v.dataset.frames));
  let frames = await framesNow();
  const sizeChanged = Date.now();
  await page.$eval('#point-size', (input) => {
    input.value = '4';
    input.dispatchEvent(new Event('input'));
  });
  await page.waitForFunction((f) => Number(document.querySelector('#viewer').dataset.frames) > f, frames, { polling: 20 });
  const fullMs = Date.now() - sizeChanged;
  const after = await drawnPixels(page);
  check(after.n > before.n, `a larger point size covers more pixels (${before.n} -> ${after.n})`);
  // Orbit with the mouse: while the button is held the subsample is drawn, then the full cloud.
  const canvas = await page.$('#viewer canvas');
  await canvas.scrollIntoViewIfNeeded();
  const box = await canvas.boundingBox();
  frames = await framesNow();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(box.x + box.width / 2 + 200, box.y + box.height / 2 + 50, { steps: 2 });
  await page.waitForFunction((f) => Number(document.querySelector('#viewer').dataset.frames) > f, frames);
  const moving = await drawnPixels(page);
  check(moving.n > 1000, `points drawn while orbiting (${moving.n} pixels)`);
  const movingMs = await page.$eval('#viewer', (v) => v.measureDrawMs(true));  // GPU waited for
  frames = await framesNow();
  await page.mouse.up();
  await page.waitForFunction((f) => Number(document.querySelector('#viewer').dataset.frames) > f, frames);
  const orbited = await drawnPixels(page);
  check(orbited.n > moving.n, `the full cloud is drawn again when the mouse is released (${moving.n} -> ${orbited.n} pixels)`);
  log(`a redraw of 2,000,000 points at size 4: ${fullMs} ms; while moving (subsample): ${movingMs.toFixed(0)} ms ` +
    '(software GL: headless chromium without a GPU)');
  await screenshot(page, 'viewer-2M-points');
  return `2M-point PLY: drawn ${loadMs} ms after making and choosing the file, ${after.n} pixels lit at size 4, ` +
    `redraw ${fullMs} ms full, ${movingMs.toFixed(0)} ms while moving (software GL)`;
}

// Instant 3D: a stereo_reconstruct job with the rig just measured; its page shows the cloud.
async function reconstructAndView(page, server, datasetId, rigJob, setDir) {
  const jobId = await submitJob(page, server, datasetId, 'stereo_reconstruct', async (p) => {
    await p.selectOption('#job-form select[name=rig]', rigJob);
  });
  await followJob(page, server, jobId, 'reconstruct');
  await page.waitForFunction(() => Number(document.querySelector('#viewer')?.dataset.frames || 0) > 0, null, { timeout: 60000 });
  const drawn = await drawnPixels(page);
  const hud = (await page.innerText('#viewer .hud')).split('\n').slice(0, 2).join(' ');
  log(`viewer on job ${jobId}: ${hud}; ${drawn.n} pixels drawn`);
  check(drawn.n > 50, `points were drawn (${drawn.n} pixels)`);
  await screenshot(page, 'viewer-stereo-reconstruct');
  const pairs = await checkReconstructPairs(page, server, jobId);
  const warned = await checkPairWarnings(page, server, datasetId, rigJob);
  const preview = await checkCloudPreview(page, server, rigJob, jobId, setDir);
  return `stereo_reconstruct job ${jobId}: ${hud}, ${drawn.n} pixels drawn; ${preview}; ${pairs}; ${warned}`;
}

// Clouds as Potree shows them: the job built a preview of its large merged cloud (under 2 M
// points and 20 MB, the same properties); the page loads the preview by default, states the full
// cloud's size on a button and loads it on request; the cloud can be coloured by height (a colour
// bar in metres) and by confidence.
async function checkCloudPreview(page, server, rigJob, firstJob, setDir) {
  // One pair on a grid twice as fine as the default one, confidence down to 0.1: a cloud of over
  // 20 MB (measured 2026-11-27: 2.5 times finer at the default 0.5 gave 10 MB, 3 times finer at
  // 0.1 gave 53.7 MB).
  const { grid } = await (await fetch(`${server.url}/api/v1/jobs/${firstJob}/result`)).json();
  check(grid && grid.step_rad > 0, `the reconstruction's result states its grid (${JSON.stringify(grid)})`);
  const first = fs.readdirSync(path.join(setDir, 'cam0')).sort()[0];
  const { id: datasetId } = await uploadDataset(page, server, 'browser-stereo-one-pair',
    copySet('one-pair', Object.fromEntries(['cam0', 'cam1'].map((cam) => [`${cam}/${first}`, path.join(setDir, cam, first)]))));
  const jobId = await submitJob(page, server, datasetId, 'stereo_reconstruct', async (p) => {
    await p.selectOption('#job-form select[name=rig]', rigJob);
    await p.fill('#job-form textarea[name=extra]', JSON.stringify({ grid_step_rad: grid.step_rad / 2, min_confidence: 0.1 }));
  });
  await followJob(page, server, jobId, null);
  await page.waitForFunction(() => Number(document.querySelector('#viewer')?.dataset.frames || 0) > 0, null, { timeout: 60000 });
  const result = await (await fetch(`${server.url}/api/v1/jobs/${jobId}/result`)).json();
  const artifacts = await (await fetch(`${server.url}/api/v1/jobs/${jobId}/artifacts`)).json();
  const full = artifacts.find((a) => a.name === result.artifact);
  check(full, `the result names its cloud (${result.artifact})`);
  const preview = artifacts.find((a) => a.name === full.name.replace(/\.ply$/, '.preview.ply'));
  const headerOf = async (name) => {
    const bytes = new Uint8Array(await (await fetch(`${server.url}/api/v1/jobs/${jobId}/artifacts/${name}`)).arrayBuffer());
    const text = new TextDecoder('latin1').decode(bytes.subarray(0, 4096));
    return { count: Number(/element vertex (\d+)/.exec(text)[1]), properties: [...text.matchAll(/property \w+ (\w+)/g)].map((m) => m[1]), bytes: bytes.length };
  };
  const fullHeader = await headerOf(full.name);
  const large = full.size > 20e6 || fullHeader.count > 2e6;
  check(large, `the merged cloud of this job is large enough to need a preview (${full.size} bytes, ${fullHeader.count} points)`);
  check(preview, `a large cloud gets a preview (${full.name}: ${full.size} bytes; artifacts ${artifacts.map((a) => a.name).join(', ')})`);
  const previewHeader = await headerOf(preview.name);
  check(preview.size <= 20e6 && previewHeader.count <= 2e6 && previewHeader.count > 0,
    `the preview is under the bound (${preview.size} bytes, ${previewHeader.count} points)`);
  check(JSON.stringify(previewHeader.properties) === JSON.stringify(fullHeader.properties),
    `the preview keeps every property (${previewHeader.properties.join(' ')})`);
  // By default: the preview, the full size stated on the button.
  const shownTitle = () => page.$eval('#viewer .hud strong', (n) => n.textContent);
  check(await shownTitle() === preview.name, `the viewer loaded the preview first (${await shownTitle()})`);
  const count = (text) => Number((/([0-9,]+) points/.exec(text) || [])[1]?.replace(/,/g, ''));
  check(count(await page.innerText('#viewer .hud')) === previewHeader.count, 'the viewer shows the preview\'s points');
  const sizeMb = (full.size / 1e6).toFixed(1);
  const [note] = await atWidths(page, 'viewer-cloud-preview', '#cloud-size-note', async () => {
    const text = (await page.innerText('#cloud-size-note')).replace(/\s+/g, ' ').trim();
    const button = (await page.innerText('#load-cloud')).trim();
    check(text.startsWith(`A preview: ${previewHeader.count.toLocaleString('en-US')} points`), `the note says a preview is shown (${text})`);
    check(button === `Load the full cloud ${full.name} (${sizeMb} MB)`, `the button states the full cloud's size (${button})`);
    return text;
  });
  // Colour by height: a colour bar in metres with a range.
  const modes = await page.$$eval('#colour-by option', (o) => o.map((x) => x.value));
  check(['height', 'range'].every((m) => modes.includes(m)) && (!fullHeader.properties.includes('confidence') || modes.includes('confidence')),
    `the cloud can be coloured by height, range and confidence (${modes.join(', ')})`);
  let frames = Number(await page.$eval('#viewer', (v) => v.dataset.frames));
  await page.selectOption('#colour-by', 'height');
  await page.waitForFunction((f) => Number(document.querySelector('#viewer').dataset.frames) > f, frames);
  const bar = await page.$eval('#cloud-colour-bar', (b) => ({ unit: b.dataset.unit, min: Number(b.dataset.min), max: Number(b.dataset.max), caption: b.querySelector('figcaption').textContent }));
  check(bar.unit === 'm' && bar.max > bar.min && /height/.test(bar.caption), `colour by height has a bar in metres (${JSON.stringify(bar)})`);
  await atWidths(page, 'viewer-cloud-by-height', '#viewer', async () => null);
  if (modes.includes('confidence')) {
    frames = Number(await page.$eval('#viewer', (v) => v.dataset.frames));
    await page.selectOption('#colour-by', 'confidence');
    await page.waitForFunction((f) => Number(document.querySelector('#viewer').dataset.frames) > f, frames);
    check(/confidence/.test(await page.textContent('#cloud-colour-bar figcaption')), 'colour by confidence has its bar');
  }
  // On request: the full cloud.
  await page.click('#load-cloud');
  await page.waitForFunction((name) => document.querySelector('#viewer .hud strong')?.textContent === name
    && Number(document.querySelector('#viewer')?.dataset.frames || 0) > 0, full.name, { timeout: 120000 });
  check(count(await page.innerText('#viewer .hud')) === fullHeader.count, `the full cloud's ${fullHeader.count} points are shown`);
  const drawn = await drawnPixels(page);
  check(drawn.n > 50, `the full cloud is drawn (${drawn.n} pixels)`);
  await atWidths(page, 'viewer-cloud-full', '#viewer', async () => null);
  log(`preview: ${preview.name} ${preview.size} bytes, ${previewHeader.count} of ${fullHeader.count} points; "${note}"; full cloud loaded on request`);
  return `preview ${previewHeader.count} of ${fullHeader.count} points (${(preview.size / 1e6).toFixed(1)} of ${sizeMb} MB) loaded first, the full cloud on request; colour by ${modes.join(', ')}`;
}

// A pair's warning in words: a confidence threshold above most pixels' confidence leaves fewer
// than half the mirror cells confident, and the page shows each pair's warning and the job's.
async function checkPairWarnings(page, server, datasetId, rigJob) {
  const jobId = await submitJob(page, server, datasetId, 'stereo_reconstruct', async (p) => {
    await p.selectOption('#job-form select[name=rig]', rigJob);
    await p.fill('#job-form textarea[name=extra]', '{"min_confidence": 0.95}');
  });
  await followJob(page, server, jobId, null);
  await page.waitForSelector('#reconstruct-pairs');
  const result = await (await fetch(`${server.url}/api/v1/jobs/${jobId}/result`)).json();
  const warned = (result.pairs || []).filter((p) => p.warning);
  check(warned.length > 0 && result.warning, `min_confidence 0.95 leaves pairs with few confident pixels (${JSON.stringify(result.pairs.map((p) => p.confident_fraction))})`);
  check((await page.textContent('#reconstruct-warning')).trim() === result.warning, `the job's warning is shown (${result.warning})`);
  for (const pair of warned) {
    const shown = (await page.textContent(`#reconstruct-pairs .range-pair[data-pair="${pair.name}"] .pair-warning`)).trim();
    check(shown === pair.warning, `pair ${pair.name} shows its warning (${shown})`);
  }
  await page.$eval('#reconstruct-pairs', (c) => c.scrollIntoView());
  await screenshot(page, 'reconstruct-warnings');
  log(`min_confidence 0.95: ${warned.length} pair warning(s) shown, e.g. "${warned[0].warning}"`);
  return `with min_confidence 0.95 the page shows "${result.warning}" and ${warned.length} pair warning(s)`;
}

// The pairs of a stereo_reconstruct job: each dense pair's range preview loads, its numbers and
// warning are shown, its range TIFF and PLY download; a pair's button puts its cloud in the viewer.
async function checkReconstructPairs(page, server, jobId) {
  const result = await (await fetch(`${server.url}/api/v1/jobs/${jobId}/result`)).json();
  await page.waitForSelector('#reconstruct-pairs');
  const pairs = result.pairs || [];
  check(pairs.length > 0, 'the result has pairs');
  const dense = pairs.filter((p) => p.range_png);
  for (const pair of pairs) {
    const block = `#reconstruct-pairs .range-pair[data-pair="${pair.name}"]`;
    const text = await page.textContent(block);
    check(text.includes(Number(pair.num_points).toLocaleString('en-US')), `pair ${pair.name} shows its ${pair.num_points} points`);
    if (pair.warning) check(text.includes(pair.warning), `pair ${pair.name} shows its warning`);
    if (!pair.range_png) continue;
    check(text.includes(`${(100 * pair.confident_fraction).toFixed(1)} % of the mirror cells`), `pair ${pair.name} shows its confident fraction`);
    check(text.includes(`${pair.median_range_m.toFixed(3)} m`), `pair ${pair.name} shows its median range`);
    await page.$eval(block, (b) => b.scrollIntoView());  // the previews load lazily, as a person scrolls
    const [[w, h]] = await imagesLoaded(page, `${block} figure.range-preview img`, `the range preview of ${pair.name}`);
    check(await page.$eval(`${block} figure.range-preview img`, (i, name) => decodeURIComponent(i.src).endsWith(`/artifacts/${name}`), pair.range_png),
      `the preview of ${pair.name} is its range_png ${pair.range_png}`);
    const cloud = pair.artifact || (pairs.length === 1 ? result.artifact : null);
    await checkDownloads(page, server, jobId, block, [pair.range_tiff, ...(cloud ? [cloud] : [])]);
    log(`pair ${pair.name}: range preview ${w}x${h}, ${pair.num_points} points, ${(100 * pair.confident_fraction).toFixed(1)} % confident` +
      `${pair.warning ? `, warning "${pair.warning}"` : ''}`);
  }
  let bars = [];
  if (dense.length) {
    [bars] = await atWidths(page, 'reconstruct-pairs', '#reconstruct-pairs', () => checkColourBars(page, '#reconstruct-pairs', dense.length));
    check(bars.every((b) => b.startsWith('Range')), `each range panorama has a range colour bar in metres (${bars.join(' | ')})`);
  }
  // The last pair's "show in 3D" button swaps the viewer's cloud.
  const last = pairs[pairs.length - 1];
  const button = await page.$(`#reconstruct-pairs .range-pair[data-pair="${last.name}"] button.view-cloud`);
  if (button && pairs.length > 1) {
    await button.click();
    await page.waitForFunction((name) => document.querySelector('#viewer .hud strong')?.textContent === name
      && Number(document.querySelector('#viewer')?.dataset.frames || 0) > 0, last.artifact, { timeout: 60000 });
    const drawn = await drawnPixels(page);
    check(drawn.n > 50, `the cloud of pair ${last.name} was drawn (${drawn.n} pixels)`);
    log(`"Show this pair in the 3D viewer" on ${last.name}: ${last.artifact} drawn, ${drawn.n} pixels`);
  }
  return `${pairs.length} pair(s) shown${dense.length ? `, ${dense.length} range preview(s) loaded with colour bars (${bars[0]})` : ''}, ` +
    'range TIFF and PLY downloads answer 200';
}

// SLAM on a synthetic sequence: the rig from a stereo-board set, the sequence uploaded with its
// ground truth, the job's page with the cloud, the trajectory, the top view and per-frame stats.
async function stepViewerSlam(page, server) {
  const sequence = synth('stereo-sequence');
  if (!sequence) throw new Skip('omnirig synth --preset stereo-sequence is not available');
  const { jobId: rigJob } = await runRelativePose(page, server, stereoSet(6));
  const tum = path.join(sequence.dir, 'trajectory.tum');
  const images = path.join(TEMP, 'sequence-images');
  fs.mkdirSync(images);
  for (const cam of ['cam0', 'cam1']) fs.cpSync(path.join(sequence.dir, cam), path.join(images, cam), { recursive: true });
  const { id } = await uploadDataset(page, server, 'browser-slam', images);
  const refused = fs.existsSync(tum) ? await uploadOneMore(page, tum) : 'no trajectory.tum';
  if (refused) log(`ground truth not in the dataset: ${refused}`);
  const jobId = await submitJob(page, server, id, 'slam', async (p) => {
    await p.selectOption('#job-form select[name=rig]', rigJob);
    if (!refused) await p.fill('#job-form input[name=ground_truth]', 'trajectory.tum');
  });
  await followJob(page, server, jobId, 'slam');
  await page.waitForFunction(() => Number(document.querySelector('#viewer')?.dataset.frames || 0) > 0, null, { timeout: 60000 });
  const drawn = await drawnPixels(page);
  const hud = (await page.innerText('#viewer .hud')).replace(/\s+/g, ' ').trim();
  check(drawn.n > 50, `map points were drawn (${drawn.n} pixels)`);
  const topInk = await page.$eval('#top-view', (c) => {
    const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
    let blue = 0;
    let orange = 0;
    for (let i = 0; i < d.length; i += 4) {
      if (d[i + 2] > 180 && d[i] < 80) blue += 1;
      if (d[i] > 200 && d[i + 1] > 120 && d[i + 1] < 180 && d[i + 2] < 60) orange += 1;
    }
    return { blue, orange };
  });
  check(topInk.blue > 50, `the top view draws the trajectory (${topInk.blue} blue pixels)`);
  if (!refused) check(topInk.orange > 50, `the top view draws the ground truth (${topInk.orange} orange pixels)`);
  const rows = await page.$$eval('#frame-stats tbody tr', (r) => r.length);
  const frames = sequence.groundTruth.frames.length;
  check(rows === frames, `per-frame statistics list every frame (${rows} of ${frames})`);
  const legend = await page.$$eval('#top-view-legend li', (items) => items.map((i) => i.dataset.key));
  check(['tracked', 'relocalised', 'relinked', 'reinitialised', 'lost'].every((k) => legend.includes(k)),
    `the top view's legend lists the states (${legend.join(', ')})`);
  await screenshot(page, 'viewer-slam');
  const errors = refused ? `no error plots (${refused})` : await checkSlamErrors(page, server, jobId);
  const loops = await checkLoopsDrawn(page, jobId, sequence.groundTruth.frames.map((f) => f.name));
  const live = await checkLivePage(page, server, rigJob, sequence.dir);
  return `slam job ${jobId}: ${hud}; ${drawn.n} pixels drawn; top view ${topInk.blue} estimate / ${topInk.orange} ground-truth pixels; ${rows} frame rows; ${errors}; ${loops}; ${live}` +
    (refused ? `; ground truth not uploaded (${refused})` : '');
}

// A live slam job's page while a robot sends its frames (here the sequence's, posted as the
// robot would): the figures count the frames as they are tracked, the top view draws the
// trajectory growing over the occupancy grid so far (the job has a dense map) and the map so far
// is shown; "Finish the run" ends it and the page shows the finished report.
async function checkLivePage(page, server, rigJob, sequenceDir) {
  const created = await fetch(`${server.url}/api/v1/jobs`, { method: 'POST', headers: { 'Content-Type': 'application/json' },
    // Keyframes 0.25 m apart on the full-resolution grid (at 640x480 a coarser one leaves few points).
    body: JSON.stringify({ type: 'slam', dataset: '', params: { rig: rigJob, live: true, dense_map: { keyframe_spacing_m: 0.25, grid_step_factor: 1 } } }) });
  check(created.status === 202, `a live slam job starts (${created.status})`);
  const { id } = await created.json();
  await page.goto(`${server.url}/#/jobs/${encodeURIComponent(id)}`);
  await page.waitForSelector('#live-card');
  const names = fs.readdirSync(path.join(sequenceDir, 'cam0')).filter((n) => /\.png$/i.test(n)).sort().slice(0, 8);
  const shown = (key) => page.$eval(`#live-figures [data-key=${key}] dd`, (n) => n.textContent.trim()).catch(() => '');
  let tracked = 0;
  for (const [i, name] of names.entries()) {
    const form = new FormData();
    for (const cam of ['cam0', 'cam1']) {
      form.append(cam, new Blob([fs.readFileSync(path.join(sequenceDir, cam, name))], { type: 'image/png' }), name);
    }
    form.append('stamp', String(10 + 0.1 * i));
    const answer = await fetch(`${server.url}/api/v1/jobs/${id}/frames`, { method: 'POST', body: form });
    check(answer.status === 200, `frame ${i} is answered (${answer.status})`);
    const body = await answer.json();
    if (body.world_from_rig) tracked += 1;
    // The page counts the frame once its event arrives.
    await page.waitForFunction((n) => document.querySelector('#live-figures [data-key=frames-tracked] dd')?.textContent.trim() === String(n),
      tracked, { timeout: 30000 });
  }
  check(tracked >= 6, `the live job tracked the sequence's frames (${tracked} of ${names.length})`);
  const received = await shown('frames-received');
  check(received === String(names.length), `frames received ${received} of ${names.length}`);
  const rate = await shown('frame-rate');
  check(/^[0-9.]+ frames\/s$/.test(rate), `the frame rate with its unit (${rate})`);
  const latency = await shown('latency');
  check(/^p50 [0-9.]+ ms, p95 [0-9.]+ ms$/.test(latency), `the latency percentiles with their unit (${latency})`);
  const skipped = await shown('frames-skipped');
  check(/^0 /.test(skipped), `no frame skipped (${skipped})`);
  await page.waitForFunction((n) => Number(document.querySelector('#live-top-view')?.dataset.poses || 0) >= n, tracked, { timeout: 30000 });
  const blue = await page.$eval('#live-top-view', (c) => {
    const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
    let n = 0;
    for (let i = 0; i < d.length; i += 4) if (d[i + 2] > 180 && d[i] < 80) n += 1;
    return n;
  });
  check(blue > 20, `the live top view draws the trajectory (${blue} blue pixels)`);
  await page.waitForFunction(() => Number(document.querySelector('#live-map-note')?.dataset.points || 0) > 0, null, { timeout: 30000 });
  const points = await page.$eval('#live-map-note', (n) => Number(n.dataset.points));
  // The grid so far, drawn under the trajectory once two keyframes are fused, with its key.
  await page.waitForFunction(() => Number(document.querySelector('#live-top-view')?.dataset.occupiedCells || 0) > 0, null, { timeout: JOB_TIMEOUT_MS });
  const occupied = await page.$eval('#live-top-view', (c) => Number(c.dataset.occupiedCells));
  const key = await page.$eval('#live-occupancy-key', (n) => n.textContent).catch(() => '');
  check(/occupied/.test(key), `the live grid's colour key is shown (${key.slice(0, 60)})`);
  const finishedNow = await (await fetch(`${server.url}/api/v1/jobs/${id}`)).json();
  check(finishedNow.state === 'running', `the grid is shown while the job runs (${finishedNow.state})`);
  await screenshot(page, 'live-slam-running');
  await page.click('#live-finish');
  await page.waitForSelector('#slam-headline', { timeout: JOB_TIMEOUT_MS });
  const done = await (await fetch(`${server.url}/api/v1/jobs/${id}`)).json();
  check(done.state === 'succeeded', `the live job finished (${done.state})`);
  return `live job ${id}: ${tracked} of ${names.length} frames tracked on its page, ${rate}, latency ${latency}, ${points} map points shown, ${occupied} occupied cells of the grid so far, finished from the page`;
}

// The errors against the ground truth as evo shows them: the headline's ATE and RPE with units,
// the translation and rotation error plotted against the distance travelled (every frame of the
// evaluation drawn, axes titled with their units), and the RPE per 1 m and 10 m segment.
async function checkSlamErrors(page, server, jobId) {
  const { evaluation } = await (await fetch(`${server.url}/api/v1/jobs/${jobId}/result`)).json();
  check(evaluation && evaluation.per_frame, 'the slam result has an evaluation with per-frame errors');
  await page.waitForSelector('#slam-errors');
  await page.waitForFunction(() => ['#translation-error-plot', '#rotation-error-plot'].every((id) => document.querySelector(id)?.dataset.points));
  const item = (key) => page.$eval(`#slam-headline [data-key=${key}] dd`, (n) => n.textContent.trim()).catch(() => '');
  const frames = evaluation.per_frame.distance_m.length;
  const [seen] = await atWidths(page, 'viewer-slam-errors', '#slam-errors', async () => {
    const ate = await item('ate');
    const rpe = await item('rpe');
    check(/^[0-9.]+ (m|cm|mm)$/.test(ate), `the headline's ATE with its unit (${ate})`);
    check(/^[0-9.]+ (m|cm|mm), [0-9.]+°$/.test(rpe), `the headline's RPE with its units (${rpe})`);
    const plots = await page.$$eval('#slam-errors canvas.line-plot', (list) => list.map((c) => {
      const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
      let ink = 0;
      for (let i = 0; i < d.length; i += 4) if (d[i + 3] > 200 && (d[i + 2] > 200 && d[i] < 160)) ink += 1;  // the blue and purple lines
      return { id: c.id, points: Number(c.dataset.points), x: c.dataset.xTitle, y: c.dataset.yTitle, ink, width: c.getBoundingClientRect().width };
    }));
    const [translation, rotation] = ['translation-error-plot', 'rotation-error-plot'].map((id) => plots.find((p) => p.id === id));
    check(translation && rotation, `both error plots are shown (${plots.map((p) => p.id).join(', ')})`);
    for (const plot of [translation, rotation]) {
      check(plot.points === frames, `${plot.id} draws every evaluated frame (${plot.points} of ${frames})`);
      check(plot.x === 'distance travelled (m)', `${plot.id}'s x axis is the distance travelled in m (${plot.x})`);
      check(plot.ink > 100 && plot.width > 200, `${plot.id} is drawn (${plot.ink} pixels of its line, ${plot.width} px wide)`);
    }
    check(/^translation error \((m|cm|mm)\)$/.test(translation.y), `the translation error's axis has its unit (${translation.y})`);
    check(rotation.y === 'rotation error (°)', `the rotation error's axis is in degrees (${rotation.y})`);
    const segments = await page.$$eval('#rpe-segments tbody tr', (rows) => rows.map((r) => ({ length: Number(r.dataset.length), text: r.innerText.replace(/\s+/g, ' ').trim() })));
    check(segments.length === evaluation.rpe_segments.length, `a row per RPE segment length (${segments.length})`);
    evaluation.rpe_segments.forEach((seg, i) => {
      const row = segments[i];
      check(row.length === seg.length_m && row.text.startsWith(`${seg.length_m} m `), `the row of ${seg.length_m} m segments (${row.text})`);
      if (seg.num_segments > 0) {
        check(new RegExp(`^${seg.length_m} m ${seg.num_segments} [0-9.]+ (m|cm|mm) [0-9.]+ % [0-9.]+°$`).test(row.text),
          `the ${seg.length_m} m RPE with units (${row.text})`);
      } else {
        check(/none: the path \([0-9.]+ (m|cm|mm)\) is shorter than/.test(row.text), `no ${seg.length_m} m segment, and why (${row.text})`);
      }
    });
    const metre = evaluation.rpe_segments.find((seg) => seg.length_m === 1 && seg.num_segments > 0);
    const rpe1 = await item('rpe-1m');
    if (metre) check(/^[0-9.]+ (m|cm|mm) \([0-9.]+ % mean\), [0-9.]+°$/.test(rpe1), `the headline's RPE per 1 m with its units (${rpe1})`);
    return { ate, rpe, rpe1, segments: segments.map((r) => r.text) };
  });
  log(`slam errors: ATE ${seen.ate}, RPE ${seen.rpe}, per 1 m ${seen.rpe1 || 'none'}; segments ${seen.segments.join(' | ')}`);
  return `error plots of ${frames} frames; ATE ${seen.ate}; RPE ${seen.rpe}; segments ${seen.segments.join(' | ')}`;
}

// Loop closures and states in the top view. A loop sequence is too long for this
// test, so the page's requests for the job's result and trajectory.json are answered with the
// real ones plus a loop from the last frame to the first and, from the middle on, a lost frame
// then relinked ones; the page must draw the loop's line and the relinked colour.
async function checkLoopsDrawn(page, jobId, names) {
  const last = names.length - 1;
  await page.route(`**/api/v1/jobs/${jobId}/result`, async (route) => {
    const response = await route.fetch();
    const result = await response.json();
    result.loops = [{ frame: names[last], frame_index: last, matched_frame: names[0], matched_frame_index: 0, inliers: 150, correction_m: 0.04, correction_deg: 0.2 }];
    await route.fulfill({ response, json: result });
  });
  await page.route(`**/api/v1/jobs/${jobId}/artifacts/trajectory.json`, async (route) => {
    const response = await route.fetch();
    const trajectory = await response.json();
    const middle = Math.floor(trajectory.frames.length / 2);
    trajectory.frames.forEach((f, i) => {
      if (i === middle) Object.assign(f, { state: 'lost', world_from_rig: null });
      if (i > middle) f.state = 'relinked';
    });
    await route.fulfill({ response, json: trajectory });
  });
  await page.reload();
  await page.waitForSelector('#top-view-legend li[data-key=loop]', { timeout: 60000 });
  await page.waitForFunction(() => document.querySelector('#top-view') !== null);
  await page.evaluate(() => new Promise((resolve) => requestAnimationFrame(() => requestAnimationFrame(resolve))));
  const ink = await page.$eval('#top-view', (c) => {
    const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
    let loop = 0;
    let relinked = 0;
    for (let i = 0; i < d.length; i += 4) {
      if (d[i] > 190 && d[i + 1] < 80 && d[i + 2] > 90 && d[i + 2] < 160) loop += 1;  // #db2777
      if (d[i] < 50 && d[i + 1] > 120 && d[i + 1] < 180 && d[i + 2] > 80 && d[i + 2] < 130) relinked += 1;  // #059669
    }
    return { loop, relinked };
  });
  const legendText = await page.innerText('#top-view-legend li[data-key=loop]');
  check(/\(1\)/.test(legendText), `the legend counts the loop (${legendText})`);
  const lostText = await page.innerText('#top-view-legend li[data-key=lost]');
  check(/\(1 frame\)/.test(lostText), `the legend counts the lost frame (${lostText})`);
  check(ink.loop > 30, `the loop's line is drawn (${ink.loop} pixels)`);
  check(ink.relinked > 20, `relinked frames are drawn in their colour (${ink.relinked} pixels)`);
  await screenshot(page, 'viewer-slam-loops');
  await page.unrouteAll({ behavior: 'ignoreErrors' });
  return `an injected loop drawn (${ink.loop} pixels), relinked frames ${ink.relinked} pixels`;
}

// A server with a bearer token: the page asks for it, then works (API calls, an upload, a
// thumbnail fetched with the token).
const TOKEN = 'browser-test-token';
async function stepAuth(page, server) {
  await page.goto(`${server.url}/#/datasets`);
  await page.waitForSelector('#auth input[type=password]');
  await screenshot(page, 'auth-asked');
  await page.fill('#auth input[type=password]', TOKEN);
  await page.click('#auth button[type=submit]');
  await page.waitForSelector('#health.ok');
  const s = calibrationSet();
  const files = {};
  for (const f of imagesIn(s.dir).slice(0, 2)) files[`cam0/${path.basename(f)}`] = path.join(s.dir, f);
  const { id, count } = await uploadDataset(page, server, 'browser-auth', copySet('auth', files));
  await page.waitForFunction((n) => [...document.querySelectorAll('.thumbs img')].filter((i) => i.complete && i.naturalWidth > 0).length === n, count);
  const anonymous = await fetch(`${server.url}/api/v1/datasets/${id}`);
  check(anonymous.status === 401, `the API refuses calls without the token (HTTP ${anonymous.status})`);
  await screenshot(page, 'auth-dataset');
  return `token asked for, then ${count} images uploaded and shown as thumbnails through the token`;
}

// ---- the first hour --------------------------------------------------------------------------

// The first hour of a new user on a fresh data folder, from the landing page: the first-run
// panel, the sample data (rendered by the server), a calibration, a rig, a SLAM run and its
// viewer, and each bad input a new user meets, checking the words the page shows.
async function stepFirstHour(page, server) {
  const api = async (p) => (await fetch(`${server.url}/api/v1${p}`)).json();
  const notes = [];
  await page.goto(`${server.url}/`);
  await page.waitForSelector('#first-run');
  const steps = await page.$$eval('#first-run li[data-step]', (items) => items.map((i) => i.textContent));
  check(steps.length === 3 && /Calibrate each camera/.test(steps[0]) && /Measure the rig/.test(steps[1]) && /Run a sequence/.test(steps[2]),
    `the panel lists the three steps (${steps.map((t) => t.slice(0, 30)).join(' | ')})`);
  await screenshot(page, 'first-hour-01-panel');

  // One click loads the sample data: three datasets rendered by "sample" jobs.
  let started = Date.now();
  await page.click('#load-sample');
  await page.waitForFunction(() => document.querySelectorAll('#sample-status [data-state=succeeded]').length === 3,
    null, { timeout: FIRST_HOUR_JOB_MS });
  notes.push(`sample data rendered in ${((Date.now() - started) / 1000).toFixed(1)} s`);
  await page.waitForSelector('#first-run li[data-step=calibrate] a.step-link[href*="type=calibration"]');
  const datasets = await api('/datasets');
  const byName = (prefix) => datasets.find((d) => d.name.startsWith(prefix));
  const mono = byName('sample: one camera');
  const sequence = byName('sample: sequence');
  check(mono && byName('sample: stereo rig') && sequence, 'the three sample datasets exist');
  // The list counts images only; the sequence's trajectory is named apart.
  const seqRow = `tr[data-dataset-id="${sequence.id}"]`;
  await page.waitForSelector(seqRow);
  const seqCount = await page.$eval(`${seqRow} td[data-images]`, (td) => td.textContent);
  check(/^20 \+ trajectory\.tum$/.test(seqCount.trim()), `the sequence shows 20 images + trajectory.tum (${seqCount})`);
  await screenshot(page, 'first-hour-02-samples');

  // Step 1: calibrate, from the step's link (the form comes with the dataset and type chosen).
  await page.click('#first-run li[data-step=calibrate] a.step-link');
  await page.waitForSelector('#job-form');
  check(await page.$eval('#job-form select[name=type]', (s) => s.value) === 'calibration', 'the link chose the calibration type');
  check(await page.$eval('#job-form select[name=dataset]', (s) => s.value) === mono.id, 'the link chose the sample dataset');
  const calJob = await submitFromForm(page);
  await followJob(page, server, calJob, 'first-hour-03-calibration', FIRST_HOUR_JOB_MS);
  await page.waitForSelector('#calibration-report');
  const calResult = await api(`/jobs/${calJob}/result`);
  check(calResult.solver.brief.includes(`Iterations: ${calResult.solver.iterations} `),
    `the solver's brief agrees with its iterations (${calResult.solver.brief} vs ${calResult.solver.iterations})`);
  const artifacts = (await api(`/jobs/${calJob}/artifacts`)).map((a) => a.name);
  check(artifacts.some((n) => /^overlay_view_000\.png$/.test(n)) && !artifacts.some((n) => /\.png\.png$/.test(n)),
    `overlays are named overlay_view_000.png (${artifacts.filter((n) => n.startsWith('overlay')).slice(0, 3)})`);
  await screenshot(page, 'first-hour-04-calibration-report');
  notes.push(`calibration RMS ${calResult.rms_px.toFixed(3)} px`);

  // Bad input: a calibration given as a slam job's rig is refused at submission, with the reason.
  await page.goto(`${server.url}/#/jobs?dataset=${encodeURIComponent(sequence.id)}&type=slam`);
  await page.waitForSelector('#job-form');
  await page.fill('#job-form textarea[name=extra]', JSON.stringify({ rig: calJob }));
  await page.click('#job-form button[type=submit]');
  const wrongRig = (await (await page.waitForSelector('#job-form .error')).textContent()).trim();
  check(wrongRig.includes('is a calibration job') && wrongRig.includes('succeeded relative_pose job'),
    `a calibration as rig is refused with the reason (${wrongRig})`);
  await screenshot(page, 'first-hour-05-wrong-rig-refused');
  notes.push(`wrong rig: "${wrongRig}"`);

  // Step 2: the rig, calibrating both cameras inside the job.
  await page.goto(`${server.url}/#/datasets`);
  await page.click('#first-run li[data-step=rig] a.step-link');
  await page.waitForSelector('#job-form select[name=type] option[value=relative_pose]:checked', { state: 'attached' });
  const rigJob = await submitFromForm(page);
  await followJob(page, server, rigJob, 'first-hour-06-rig', FIRST_HOUR_JOB_MS);
  await page.waitForSelector('#stereo-report');
  const dropped = (await page.textContent('#dropped-pairs h2')).trim();
  check(/^Pairs left out: \d+ of \d+$/.test(dropped), `the report says which pairs were left out (${dropped})`);
  await screenshot(page, 'first-hour-07-rig-report');
  notes.push(`rig: baseline ${(await page.textContent('#baseline')).trim()}; ${dropped}`);

  // Step 3: the sequence with the rig and its ground truth; its page shows the map.
  await page.goto(`${server.url}/#/datasets`);
  await page.click('#first-run li[data-step=sequence] a.step-link');
  await page.waitForSelector('#job-form select[name=rig]');
  await page.selectOption('#job-form select[name=rig]', rigJob);
  // The pickers name the jobs: type, dataset name, time and a short id, never a full id.
  const rigChoice = await page.$eval('#job-form select[name=rig]', (s) => s.selectedOptions[0].textContent);
  check(!FULL_ID.test(rigChoice) && rigChoice.includes('sample: stereo rig') && rigChoice.includes(rigJob.slice(0, 8)),
    `the rig picker names the job (${rigChoice})`);
  await checkNoIds(page, '#job-form select[name=dataset]', 'the dataset picker');
  check(await page.getAttribute('#job-form input[name=ground_truth]', 'placeholder').then((t) => t.includes('trajectory.tum')),
    'the ground truth\'s placeholder names the sample\'s trajectory.tum');
  await page.fill('#job-form input[name=ground_truth]', 'trajectory.tum');
  // The dense map is a checkbox with its voxel size (params.dense_map.voxel_m).
  await page.check('#job-form input[name=dense_map]');
  await page.fill('#job-form input[name=voxel_m]', '0.05');
  const slamJob = await submitFromForm(page);
  const slamParams = (await api(`/jobs/${slamJob}`)).params;
  check(slamParams.dense_map && slamParams.dense_map.voxel_m === 0.05, `the checkbox asked for a dense map (${JSON.stringify(slamParams)})`);
  await followJob(page, server, slamJob, 'first-hour-08-slam', FIRST_HOUR_JOB_MS);
  await page.waitForFunction(() => Number(document.querySelector('#viewer')?.dataset.frames || 0) > 0, null, { timeout: 60000 });
  const drawn = await drawnPixels(page);
  check(drawn.n > 50, `the slam job's map is drawn (${drawn.n} pixels)`);
  const summary = (await page.textContent('#job-status .grow > div:nth-child(3)')).trim();
  check(/^done\b/.test(summary), `a succeeded job ends on "done" and its summary (${summary})`);
  await screenshot(page, 'first-hour-09-slam-viewer');
  notes.push(`slam: ${summary}`);
  notes.push(await checkSlamAtAGlance(page, server, slamJob));

  notes.push(await firstHourBadInputs(page, server, { mono, rigJob }));
  return notes.join('; ');
}

// The slam job's page as a robotics user reads it: the headline (frames tracked, keyframes, loops,
// ATE and RPE with units, frame rate) agreeing with the result, the occupancy grid over the
// trajectory with its key, names instead of ids, and every artifact in one zip.
async function checkSlamAtAGlance(page, server, jobId) {
  const result = await (await fetch(`${server.url}/api/v1/jobs/${jobId}/result`)).json();
  await page.waitForSelector('#slam-headline');
  await checkNoIds(page, '#job-title', 'the slam job\'s title');
  await checkNoIds(page, '#job-status', 'the slam job\'s status');
  const item = (key) => page.$eval(`#slam-headline [data-key=${key}] dd`, (n) => n.textContent.trim()).catch(() => '');
  const [headline] = await atWidths(page, 'first-hour-09b-slam-headline', '#slam-headline', async () => {
    const shown = {};
    for (const key of ['frames-tracked', 'keyframes', 'loops', 'ate', 'rpe', 'frame-rate']) shown[key] = await item(key);
    check(shown['frames-tracked'].startsWith(`${result.num_tracked} of ${result.frames.length}`), `frames tracked (${shown['frames-tracked']})`);
    check(shown.keyframes === String(result.num_keyframes), `keyframes (${shown.keyframes})`);
    check(shown.loops === String(result.loops.length), `loop closures (${shown.loops})`);
    check(result.evaluation, 'the sample sequence has a ground truth: the result has an evaluation');
    check(/^[0-9.]+ (m|cm|mm)$/.test(shown.ate), `ATE with its unit (${shown.ate})`);
    check(/^[0-9.]+ (m|cm|mm), [0-9.]+°$/.test(shown.rpe), `RPE with its units (${shown.rpe})`);
    check(/^[0-9.]+ frames\/s$/.test(shown['frame-rate']), `the frame rate with its unit (${shown['frame-rate']})`);
    const visible = await page.$eval('#slam-headline', (n) => n.getBoundingClientRect().width > 0);
    check(visible, 'the headline is visible');
    return shown;
  });
  // The per-frame table and the summary speak in words: no raw keys such as num_scale_inliers.
  const headers = await page.$$eval('#frame-stats thead th', (ths) => ths.map((t) => t.textContent));
  check(headers.includes('scale inliers') && !headers.some((h) => /_/.test(h)), `the per-frame columns are named in words (${headers.join(', ')})`);
  const summaryKeys = await page.$$eval('#result-summary dt', (dts) => dts.map((d) => d.textContent));
  check(!summaryKeys.some((k) => /_/.test(k)), `the summary is named in words (${summaryKeys.join(', ')})`);
  // The occupancy grid of the dense map, over the trajectory, with its key.
  await page.waitForSelector('#occupancy-key');
  const key = await page.textContent('#occupancy-key');
  check(/occupied/.test(key) && /free/.test(key) && /unknown/.test(key) && /cells of [0-9.]+ (cm|mm|m)/.test(key), `the occupancy key (${key})`);
  const grid = await page.$eval('#top-view', (c) => {
    const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
    let unknown = 0;
    for (let i = 0; i < d.length; i += 4) if (d[i] === 203 && d[i + 1] === 213 && d[i + 2] === 225) unknown += 1;
    return unknown;
  });
  check(grid > 100, `the occupancy grid is drawn on the top view (${grid} pixels of unknown cells)`);
  await atWidths(page, 'first-hour-09c-slam-occupancy', '#top-view-card', async () => null);
  const zipped = await checkZipDownload(page, server, jobId);
  // The 3D viewer page lists the job with its clouds and their sizes before any download.
  await page.goto(`${server.url}/#/viewer`);
  const row = await page.waitForSelector(`#cloud-jobs tr[data-job-id="${jobId}"]`);
  const clouds = await row.$$eval('a.cloud-link', (links) => links.map((a) => `${a.dataset.artifact} ${a.nextSibling.textContent.trim()}`));
  check(clouds.some((c) => /^map\.ply [0-9.]+ (B|kB|MB|GB)$/.test(c)) && clouds.some((c) => /^dense_map\.ply /.test(c)),
    `the viewer lists the slam job's clouds with their sizes (${clouds.join(', ')})`);
  await checkNoIds(page, '#cloud-jobs', 'the viewer\'s list of jobs');
  await atWidths(page, 'first-hour-09d-viewer-list', '#cloud-jobs', async () => null);
  return `slam headline: ${Object.entries(headline).map(([k, v]) => `${k} ${v}`).join(', ')}; occupancy grid drawn; ${zipped}; ` +
    `viewer lists ${clouds.join(', ')}`;
}

// Submits the job form as it is; returns the new job's id.
async function submitFromForm(page) {
  await page.click('#job-form button[type=submit]');
  const outcome = await page.waitForSelector('#job-form .notice a, #job-form .error');
  const text = (await outcome.textContent()).trim();
  check(await outcome.evaluate((n) => n.closest('.error') === null), `the form's job was accepted (${text})`);
  return outcome.getAttribute('data-job-id');
}

// The bad inputs of a first hour: an empty dataset, a file that is not an image, a file the page
// skips, each job type's example parameters, and a job that fails.
async function firstHourBadInputs(page, server, { mono, rigJob }) {
  await page.goto(`${server.url}/#/datasets`);
  await page.fill('input[name=name]', 'my first dataset');
  await page.click('button:has-text("Create dataset")');
  await page.waitForURL(/#\/datasets\/.+/);
  const id = decodeURIComponent(page.url().split('#/datasets/')[1]);
  await page.waitForSelector('#image-count');
  check((await page.textContent('#image-count')) === '0', 'an empty dataset shows 0 images');

  // Every job type's example "other parameters" passes the server's checks: each submission is
  // refused only because the dataset is empty.
  for (const type of ['calibration', 'relative_pose', 'stereo_reconstruct', 'slam']) {
    await page.goto(`${server.url}/#/jobs?dataset=${encodeURIComponent(id)}&type=${type}`);
    await page.waitForSelector('#job-form textarea[name=extra]');
    const example = (await page.getAttribute('#job-form textarea[name=extra]', 'placeholder')).replace(/^e\.g\. /, '');
    if (await page.$('#job-form select[name=rig]')) await page.selectOption('#job-form select[name=rig]', rigJob);
    await page.fill('#job-form textarea[name=extra]', example);
    await page.click('#job-form button[type=submit]');
    const refusal = (await (await page.waitForSelector('#job-form .error')).textContent()).trim();
    check(/has no images/.test(refusal), `the ${type} example ${example} is valid (refused only for the empty dataset: ${refusal})`);
  }

  // A file that is not an image (named like one) and one the page skips, in one folder.
  await page.goto(`${server.url}/#/datasets/${encodeURIComponent(id)}`);
  await page.waitForSelector('input[name=folder]');
  const folder = path.join(TEMP, 'first-hour-folder');
  fs.mkdirSync(path.join(folder, 'cam0'), { recursive: true });
  fs.writeFileSync(path.join(folder, 'cam0', 'notes.png'), 'my notes, not a picture');
  fs.writeFileSync(path.join(folder, 'readme.txt'), 'about these images');
  // Three images without a partner in the other camera: the relative_pose job below fails.
  fs.mkdirSync(path.join(folder, 'cam1'), { recursive: true });
  for (const [i, name] of ['view_000.png', 'view_001.png', 'view_002.png'].entries()) {
    const bytes = Buffer.from(await (await fetch(`${server.url}/api/v1/datasets/${mono.id}/images/${name}`)).arrayBuffer());
    fs.writeFileSync(path.join(folder, i < 2 ? 'cam0' : 'cam1', `pair_${i}.png`), bytes);
  }
  await page.setInputFiles('input[name=folder]', folder);
  await page.waitForSelector('#upload-finished');
  const row = await page.waitForSelector('.upload-row.failed');
  const rowText = (await row.textContent()).trim();
  const percent = await row.$eval('[role=progressbar]', (b) => b.getAttribute('aria-valuenow'));
  check(rowText.includes('not an image: skip it'), `a non-image is refused in words (${rowText})`);
  check(rowText.split('notes.png').length === 2, `the refused file is named once (${rowText})`);
  check(percent !== '100', `the bar of a refused file is not at 100 % (${percent} %)`);
  const skipped = (await page.textContent('#upload-skipped')).trim();
  check(skipped.includes('readme.txt'), `the skipped file is named (${skipped})`);
  const finished = (await page.textContent('#upload-finished')).trim();
  check(!/drop them again/.test(finished) && /\b1 file\(s\) not stored/.test(finished),
    `the summary counts the one refused file and does not ask to drop it again (${finished})`);
  await page.waitForFunction(() => document.querySelector('#image-count')?.textContent === '3');
  await page.waitForFunction(() => [...document.querySelectorAll('.thumbs img')].filter((i) => i.complete && i.naturalWidth > 0).length === 3);
  const tile = await page.$eval('.thumbs img', (i) => { const r = i.getBoundingClientRect(); return [r.width, r.height]; });
  check(tile[0] >= 200 && Math.abs(tile[0] - tile[1]) < 2, `thumbnails are large square tiles (${tile.map(Math.round).join('×')})`);
  await screenshot(page, 'first-hour-10-upload-errors');

  // A job that fails (cam0 images without cam1 partners): readable lines, a red bar, Retry.
  await page.goto(`${server.url}/#/jobs?dataset=${encodeURIComponent(id)}&type=relative_pose`);
  await page.waitForSelector('#job-form');
  const failedJob = await submitFromForm(page);
  await page.goto(`${server.url}/#/jobs/${encodeURIComponent(failedJob)}`);
  await page.waitForSelector('#job-status[data-state=failed]', { timeout: FIRST_HOUR_JOB_MS });
  const why = (await page.textContent('#job-error')).trim();
  const lines = await page.$$eval('#job-error li', (items) => items.map((i) => i.textContent));
  check(lines.length === 3 && lines.some((l) => l.includes('cam1/pair_2.png has no cam0/pair_2.png')),
    `the failed job's reasons are listed one a line (${JSON.stringify(lines)}; ${why})`);
  check(!/\.(cc|h):\d+/.test(why), `no source location in the message a person reads (${why})`);
  check(await page.$('#job-status .progress.failed'), 'the failed job\'s bar is red');
  await page.click('#job-status button[data-action=retry]');
  const edited = await page.waitForSelector('.retry-editor textarea[name=retry_params]');
  check(JSON.parse(await edited.inputValue()).board, 'Retry offers the parameters to edit');
  await screenshot(page, 'first-hour-11-failed-job');
  await page.goto(`${server.url}/#/jobs`);
  const listRow = `#job-list tr[data-job-id="${failedJob}"]`;
  await page.waitForSelector(`${listRow} a:has-text("why")`);
  const listLine = (await page.textContent(`${listRow} .error-text`)).trim();
  check(listLine.length <= 160 && listLine.includes('(+2 more)'), `the list keeps one short line (${listLine})`);
  await screenshot(page, 'first-hour-12-jobs-list');
  // Retry from the list opens the job with its parameters to edit.
  await page.click(`${listRow} button[data-action=retry]`);
  await page.waitForSelector('.retry-editor textarea[name=retry_params]');
  check(page.url().includes(`#/jobs/${failedJob}`), `Retry in the list opens the job's page (${page.url()})`);
  return `bad inputs: "${rowText}", "${skipped}", failed job "${why.slice(0, 120)}"`;
}

// A dataset holding a robot's recording (a ROS 1 bag written by python3-rosbag): the job forms
// offer its image topics (not its other topics), guess cam0's and cam1's from their names, and
// send them as the params "recording" with "topic" or "topics".
async function stepRecording(page, server) {
  const written = path.join(TEMP, 'bags');
  const writer = spawnSync('/usr/bin/python3', [path.join(SOURCE_DIR, 'testing/recordings/write_ros1_bags.py'), written]);
  check(writer.status === 0, `python3-rosbag wrote the bags (${writer.stderr})`);
  const created = await (await fetch(`${server.url}/api/v1/datasets`, {
    method: 'POST', headers: { 'content-type': 'application/json' }, body: JSON.stringify({ name: 'browser-recording' }),
  })).json();
  const put = await fetch(`${server.url}/api/v1/datasets/${created.id}/images/run.bag`, {
    method: 'PUT', headers: { 'content-type': 'application/octet-stream' }, body: fs.readFileSync(path.join(written, 'images_none.bag')),
  });
  check(put.status === 201, `the bag was stored (${put.status})`);
  const imageTopics = ['/bayer/image_raw', '/cam0/image_raw', '/cam0/image_raw/compressed', '/cam1/image_raw'];
  // The stereo jobs: cam0's and cam1's topics, guessed from their names.
  await page.goto(`${server.url}/#/jobs?dataset=${encodeURIComponent(created.id)}`);
  await page.waitForSelector('#job-form');
  await page.selectOption('#job-form select[name=type]', 'relative_pose');
  await page.selectOption('#job-form select[name=dataset]', created.id);
  await page.waitForSelector('#job-form select[name=topic_cam1]');
  const offered = await page.$$eval('#job-form select[name=topic_cam0] option', (o) => o.map((x) => x.value));
  check(JSON.stringify(offered) === JSON.stringify(imageTopics), `the image topics are offered, /note is not (${offered})`);
  check(await page.inputValue('#job-form select[name=topic_cam0]') === '/cam0/image_raw', 'cam0 topic guessed');
  check(await page.inputValue('#job-form select[name=topic_cam1]') === '/cam1/image_raw', 'cam1 topic guessed');
  await screenshot(page, 'recording-topics');
  // A calibration from one topic: the params the page sends.
  const id = await submitJob(page, server, created.id, 'calibration', async (p) => {
    await fillBoard(p, { cols: 7, rows: 5, square_size_mm: 30 });
    await p.waitForSelector('#job-form select[name=topic]');
    await p.selectOption('#job-form select[name=topic]', '/cam0/image_raw/compressed');
  });
  const job = await (await fetch(`${server.url}/api/v1/jobs/${id}`)).json();
  check(job.params.recording === 'run.bag' && job.params.topic === '/cam0/image_raw/compressed' && !job.params.topics,
    `the job reads the chosen topic (${JSON.stringify(job.params)})`);
  await fetch(`${server.url}/api/v1/jobs/${id}/cancel`, { method: 'POST' });
  return 'recording topics offered and submitted';
}

const STEPS = { recording: stepRecording, first_hour: stepFirstHour, datasets: stepDatasets, calibration: stepCalibration, stereo: stepStereo, viewer_ply: stepViewerPly, viewer_slam: stepViewerSlam, auth: stepAuth };

async function main() {
  const step = STEPS[ARGS.step];
  if (!step) throw new Error(`unknown step ${ARGS.step}; one of ${Object.keys(STEPS).join(', ')}`);
  if (!fs.existsSync(path.join(WEB_DIR, 'node_modules/playwright-core'))) {
    throw new Skip(`playwright-core is not installed in ${WEB_DIR}/node_modules (run ./omnirig.sh or npm ci in web/)`);
  }
  if (!fs.existsSync(CHROMIUM)) throw new Skip(`no chromium at ${CHROMIUM}`);
  const server = await startServer(ARGS.step === 'auth' ? ['--token', TOKEN] : []);
  let browser = null;
  try {
    browser = await launchBrowser();
    log('chromium started');
    try {
      const summary = await step(browser.page, server);
      check(!browser.page.pageErrors.length, `no uncaught errors in the page (${browser.page.pageErrors.join('; ')})`);
      log('PASSED:', summary);
    } catch (e) {
      if (!(e instanceof Skip)) await screenshot(browser.page, `${ARGS.step}-failure`).catch(() => {});
      throw e;
    }
  } finally {
    if (browser) await browser.context.close().catch(() => {});
    await server.stop();
  }
}

main().then(() => {
  fs.rmSync(TEMP, { recursive: true, force: true });
  process.exit(0);
}, (e) => {
  const logFile = path.join(TEMP, 'server.log');
  if (!(e instanceof Skip) && fs.existsSync(logFile)) console.log('--- server log (tail) ---\n' + fs.readFileSync(logFile, 'utf8').slice(-3000));
  fs.rmSync(TEMP, { recursive: true, force: true });
  if (e instanceof Skip) {
    log('SKIPPED:', e.message);
    process.exit(SKIP);
  }
  console.error(`[browser/${ARGS.step}] FAILED:`, e.stack || e.message);
  process.exit(1);
});
