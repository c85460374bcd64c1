// The first-run panel of the landing page: the three steps of a first hour (calibrate each
// camera, measure the rig, run a sequence) with links, and sample data loaded with one click.
// The samples are rendered on the server by "sample" jobs (omnirig synth's presets, small), one
// dataset per step; the steps' links then open the job form on them.

import { asList, get, post } from './api.js';
import { clear, el, errorBox, poll, progressBar } from './ui.js';

const HIDDEN_KEY = 'omnirig.firstRunHidden';

// One sample dataset per step: its name, the preset the server renders, the job to run on it.
export const SAMPLES = [
  { step: 'calibrate', name: 'sample: one camera (board views)', preset: 'mono-calib', jobType: 'calibration' },
  { step: 'rig', name: 'sample: stereo rig (board pairs)', preset: 'stereo-board', jobType: 'relative_pose' },
  { step: 'sequence', name: 'sample: sequence (moving rig)', preset: 'stereo-sequence', jobType: 'slam' },
];

const STEPS = [
  { id: 'calibrate', title: 'Calibrate each camera',
    text: ['Create a dataset of 10–20 images of a checkerboard seen by one camera (tilted, near and far, all over the mirror), ',
      'then submit a ', el('code', 'calibration'), ' job with the board\'s inner corners and square size. Do it once per camera.'] },
  { id: 'rig', title: 'Measure the rig',
    text: ['Create a dataset of board pairs, one folder per camera (', el('code', 'cam0/'), ' and ', el('code', 'cam1/'),
      ', pairs matched by file name), then a ', el('code', 'relative_pose'), ' job: it uses the calibrations of step 1, ',
      'or calibrates both cameras itself.'] },
  { id: 'sequence', title: 'Run a sequence',
    text: ['Create a dataset of the rig\'s frames (', el('code', 'cam0/'), ' and ', el('code', 'cam1/'), ', plus an optional ',
      el('code', '.tum'), ' ground truth), then a ', el('code', 'slam'), ' job (or ', el('code', 'stereo_reconstruct'),
      ') with the rig of step 2 as "rig". Its page shows the 3D map and the trajectory.'] },
];

// Renders the panel into `container`; `onDatasetsChanged` runs when sample datasets appear or
// fill. Returns a cleanup function.
export async function renderFirstRun(container, onDatasetsChanged) {
  let stopPolling = null;
  const draw = async () => {
    if (stopPolling) stopPolling();
    stopPolling = null;
    if (localStorage.getItem(HIDDEN_KEY)) {
      clear(container, el('p', el('a', {
        href: '#/datasets',
        onclick: (e) => {
          e.preventDefault();
          localStorage.removeItem(HIDDEN_KEY);
          draw();
        },
      }, 'Show the first-hour guide')));
      return;
    }
    let samples;
    try {
      samples = await sampleState();
    } catch (err) {
      clear(container, errorBox(err, 'Could not read the sample data'));
      return;
    }
    const status = el('div.sample-status#sample-status');
    // A sample whose job failed or was canceled can be loaded again (into the same dataset).
    const usable = (s) => s.dataset && s.job && !['failed', 'canceled'].includes(s.job.state);
    const loaded = samples.every(usable);
    const button = el('button.primary#load-sample', { type: 'button', disabled: loaded, onclick: load }, loaded ? 'Sample data loaded' : 'Load the sample data');
    clear(container, el('div.card.first-run#first-run',
      el('div.row', el('h2.grow', 'Your first hour'),
        el('button', { type: 'button', onclick: () => { localStorage.setItem(HIDDEN_KEY, '1'); draw(); } }, 'Hide')),
      el('ol', STEPS.map((step) => stepItem(step, samples.find((s) => s.step === step.id)))),
      el('p', button, ' ', el('span.muted', 'Three small synthetic datasets, one per step, rendered by the server with ',
        el('code', 'omnirig synth'), ' (640×480; a few seconds each). Their boards have 8 × 6 inner corners of 40 mm.')),
      status));
    showSampleJobs(status, samples);
    if (samples.some((s) => s.job && !['succeeded', 'failed', 'canceled'].includes(s.job.state))) {
      stopPolling = poll(status, 1000, async () => {
        const now = await sampleState();
        showSampleJobs(status, now);
        if (now.every((s) => !s.job || ['succeeded', 'failed', 'canceled'].includes(s.job.state))) {
          onDatasetsChanged && onDatasetsChanged();
          draw();
        }
      });
    }

    async function load() {
      button.disabled = true;
      try {
        for (const sample of samples) {
          if (usable(sample)) continue;
          const dataset = sample.dataset || await post('/datasets', { name: sample.name });
          await post('/jobs', { type: 'sample', dataset: dataset.id, params: { preset: sample.preset } });
        }
      } catch (err) {
        status.append(errorBox(err, 'Could not load the sample data'));
        button.disabled = false;
        return;
      }
      onDatasetsChanged && onDatasetsChanged();
      draw();
    }
  };
  await draw();
  return () => stopPolling && stopPolling();
}

// Each sample: its dataset (when created) and its newest "sample" job.
async function sampleState() {
  const [datasets, jobs] = await Promise.all([get('/datasets'), get('/jobs?type=sample&limit=100')]);
  const jobList = asList(jobs, 'jobs');
  return SAMPLES.map((sample) => {
    const dataset = asList(datasets, 'datasets').find((d) => d.name === sample.name) || null;
    const job = dataset ? jobList.find((j) => (j.dataset ?? j.dataset_id) === dataset.id) || null : null;
    return { ...sample, dataset, job };
  });
}

function stepItem(step, sample) {
  const ready = sample && sample.dataset && sample.job && sample.job.state === 'succeeded';
  const id = ready ? encodeURIComponent(sample.dataset.id) : '';
  return el('li', { dataset: { step: step.id } }, el('strong', step.title), ': ', step.text, ' ',
    ready
      ? el('a.step-link', { href: `#/jobs?dataset=${id}&type=${sample.jobType}` }, 'Try it on the sample →')
      : el('a.step-link', { href: '#/datasets' }, 'Create a dataset below →'));
}

function showSampleJobs(container, samples) {
  const rows = samples.filter((s) => s.job).map((s) => {
    const p = s.job.progress || {};
    const failed = s.job.state === 'failed';
    return el('div.row', { dataset: { sample: s.preset, state: s.job.state } },
      el('span.grow', el('a', { href: `#/datasets/${encodeURIComponent(s.dataset.id)}` }, s.name)),
      el('a.mono', { href: `#/jobs/${encodeURIComponent(s.job.id)}` }, s.job.state),
      el('div', { style: 'flex: 0 0 220px' }, progressBar(s.job.state === 'succeeded' ? 1 : p.fraction || 0,
        s.job.state === 'succeeded' ? 'ready' : failed ? 'failed' : undefined, failed)),
      failed ? el('span.error-text', (s.job.error && s.job.error.message) || 'failed') : null);
  });
  clear(container, rows);
}
