// Jobs page: a form per job type, the live list of jobs (progress bar, stage, ETA, cancel, retry,
// delete, errors in plain words), and one job's page with its report and artifacts.

import { API, asList, del, get, getToken, post } from './api.js';
import { clear, el, errorBox, errorLines, explainJobError, formatDuration, formatTime, poll, progressBar, shortJobError, showError } from './ui.js';
import { renderArtifacts } from './artifacts.js';
import { shortId } from './labels.js';
import { isLiveSlam, renderLiveReport } from './live_report.js';

export const JOB_TYPES = {
  calibration: 'Calibration of one camera (unified model)',
  relative_pose: 'Stereo rig: relative pose of cam1 in cam0',
  stereo_reconstruct: 'Instant 3D from stereo pairs',
  slam: 'Stereo SLAM on a sequence',
};
// An example of the "other parameters" each job type accepts (each is valid for its type: the
// browser tests submit them).
export const EXTRA_PLACEHOLDERS = {
  calibration: '{"options": {"fix": ["k5", "alpha"]}}',
  relative_pose: '{"sync_false_alarm_rate": 0.01}',
  stereo_reconstruct: '{"method": "dense", "min_confidence": 0.5}',
  slam: '{"options": {"max_features": 1500}}',
};
const TERMINAL = new Set(['succeeded', 'failed', 'canceled', 'cancelled']);
const POLL_MS = 1000;
const EVENT_POLL_MS = 5000;  // polling while server events arrive: a safety net only
const LIST_LIMIT = 200;  // the newest jobs shown in the list

export async function render(view, id, query) {
  return id ? renderJob(view, id, query && query.get('retry') === '1') : renderJobs(view, query);
}

// ---- live updates -----------------------------------------------------------------------------

// Job state and progress pushed by the server (GET /api/v1/events, Server-Sent Events "job")
// when it offers them: `onJob(data)` runs on each event. The pages poll anyway (more slowly
// while events arrive), so a server without events, or a dropped stream, changes nothing but
// the delay. EventSource cannot send the bearer token: with a token, polling only.
export function subscribeJobEvents(onJob, jobId = '') {
  if (typeof EventSource === 'undefined' || getToken()) return { live: () => false, close: () => {} };
  let lastEvent = 0;
  let pending = null;  // events arrive with every progress step: the page redraws at most every 300 ms
  const source = new EventSource(`${API}/events${jobId ? `?job=${encodeURIComponent(jobId)}` : ''}`);
  const onEvent = (e) => {
    lastEvent = Date.now();
    let data;
    try {
      data = JSON.parse(e.data);
    } catch (_) {
      return;  // a malformed event: the next poll shows the truth
    }
    if (pending) return;
    pending = setTimeout(() => {
      pending = null;
      onJob(data);
    }, 300);
  };
  source.addEventListener('job', onEvent);
  source.addEventListener('job_deleted', onEvent);
  source.onerror = () => {
    // No events route (404) or a dropped stream: stop; polling carries on.
    if (source.readyState === EventSource.CLOSED || !lastEvent) source.close();
  };
  return {
    live: () => Date.now() - lastEvent < 30000,
    close: () => {
      clearTimeout(pending);
      source.close();
    },
  };
}

// ---- the form ---------------------------------------------------------------------------------

function boardFields() {
  return el('fieldset.full.board', el('legend', 'Board'),
    el('label', 'type ', el('select', { name: 'board_type' },
      el('option', { value: 'checkerboard' }, 'checkerboard'), el('option', { value: 'charuco' }, 'ChArUco'))), ' ',
    el('label', 'inner corners: cols ', el('input', { name: 'cols', type: 'number', min: 2, value: 8, style: 'width:5em' })), ' ',
    el('label', 'rows ', el('input', { name: 'rows', type: 'number', min: 2, value: 6, style: 'width:5em' })), ' ',
    el('label', 'square (mm) ', el('input', { name: 'square_size_mm', type: 'number', min: 0.1, step: 'any', value: 40, style: 'width:6em' })),
    el('span.charuco', ' ',
      el('label', 'marker (mm) ', el('input', { name: 'marker_size_mm', type: 'number', min: 0.1, step: 'any', value: 30, style: 'width:6em' })), ' ',
      el('label', 'ArUco dictionary (OpenCV id) ', el('input', { name: 'aruco_dictionary', type: 'number', min: 0, value: 0, style: 'width:5em' }))));
}

// A dataset as people name it: its name with a short id to tell namesakes apart.
export function datasetLabel(dataset, id) {
  const name = dataset && dataset.name;
  return name ? `${name} · ${shortId(id ?? dataset.id)}` : shortId(id ?? (dataset && dataset.id));
}

// An earlier job in a picker: what it ran on and when, its short id last.
export function jobLabel(job, datasetNames) {
  const datasetId = job.dataset ?? job.dataset_id ?? '';
  const name = datasetNames && datasetNames.get(datasetId);
  return `${job.type} of “${name || shortId(datasetId)}” · ${formatTime(job.finished_at || job.created_at)} · ${shortId(job.id)}`;
}

function jobOption(job, datasetNames) {
  return el('option', { value: job.id, title: job.id }, jobLabel(job, datasetNames));
}

// The slam job's ground truth: one of the dataset's .tum files (offered as suggestions), and
// the dense map with its voxel size (params.dense_map.voxel_m, api/slam_job.cc).
function slamFields() {
  return [
    el('label', 'Ground truth'),
    el('span', el('input', { name: 'ground_truth', list: 'tum-files', size: 28,
      placeholder: 'optional: a TUM file of the dataset, e.g. trajectory.tum' }), el('datalist#tum-files')),
    el('label', 'Dense map'),
    el('span.dense-map-fields',
      el('label', el('input', { name: 'dense_map', type: 'checkbox' }),
        ' fuse a dense map (dense_map.ply) and an occupancy grid for navigation'), ' ',
      el('label', 'voxel size ', el('input', { name: 'voxel_m', type: 'number', min: 0.005, max: 1, step: 'any',
        value: 0.02, style: 'width:6em' }), ' m')),
  ];
}

// The job types that can read a recording's image topics instead of the dataset's images, and
// how many cameras they read (api/recording_input.h: "topic" for one, "topics" for two).
const RECORDING_CAMERAS = { calibration: 1, relative_pose: 2, stereo_reconstruct: 2, slam: 2 };
const IMAGE_TYPES = new Set(['sensor_msgs/Image', 'sensor_msgs/msg/Image',
  'sensor_msgs/CompressedImage', 'sensor_msgs/msg/CompressedImage']);

// The recording fields: filled by offerRecordings when the dataset holds a recording.
function recordingFields() {
  return el('fieldset.full.recording', { hidden: true }, el('legend', 'Recording'),
    el('label', 'frames from ', el('select', { name: 'recording' })), ' ',
    el('span.recording-topics'));
}

// The topic pickers of one recording: its image topics only, cam0's and cam1's guessed from
// their names (cam0/left, cam1/right) for the stereo jobs.
function topicPickers(recording, cameras) {
  const topics = (recording.topics || []).filter((t) => IMAGE_TYPES.has(t.type)).map((t) => t.name);
  const guess = (words, fallback) => topics.find((t) => words.some((w) => t.includes(w))) || topics[fallback] || '';
  const picker = (name, chosen) => el('select', { name },
    topics.map((t) => el('option', { value: t, selected: t === chosen }, t)));
  if (cameras === 1) return [el('label', 'topic ', picker('topic', guess(['cam0', 'left'], 0)))];
  return [el('label', 'cam0 topic ', picker('topic_cam0', guess(['cam0', 'left'], 0))), ' ',
    el('label', 'cam1 topic ', picker('topic_cam1', guess(['cam1', 'right'], 1)))];
}

// The fields that depend on the job type; earlier results are offered from succeeded jobs.
function typeFields(type, succeeded, datasetNames) {
  const calibrations = succeeded.filter((j) => j.type === 'calibration');
  const rigs = succeeded.filter((j) => j.type === 'relative_pose');
  const pick = (name, jobs, optional) => el('select', { name },
    optional ? el('option', { value: '' }, optional) : null, jobs.map((j) => jobOption(j, datasetNames)));
  const none = (what) => el('span.muted', `no succeeded ${what} job yet`);
  const fields = typeFieldsWithoutRecording(type, succeeded, datasetNames, pick, none, calibrations, rigs);
  return RECORDING_CAMERAS[type] ? [...fields, recordingFields()] : fields;
}

function typeFieldsWithoutRecording(type, succeeded, datasetNames, pick, none, calibrations, rigs) {
  switch (type) {
    case 'calibration':
      return [boardFields()];
    case 'relative_pose':
      return [boardFields(),
        el('label', 'cam0 calibration'), calibrations.length ? pick('cal_cam0', calibrations, 'calibrate inside this job') : none('calibration'),
        el('label', 'cam1 calibration'), calibrations.length ? pick('cal_cam1', calibrations, 'calibrate inside this job') : none('calibration')];
    case 'stereo_reconstruct':
      return [el('label', 'Rig (relative pose)'), rigs.length ? pick('rig', rigs) : none('relative_pose')];
    case 'slam':
      return [el('label', 'Rig (relative pose)'), rigs.length ? pick('rig', rigs) : none('relative_pose'), ...slamFields()];
    default:
      return [];
  }
}

// Builds the job's params from the form; `extra` (JSON) is merged last so any option can be set.
export function paramsFromForm(type, form) {
  const value = (name) => (form.elements[name] ? form.elements[name].value.trim() : '');
  const params = {};
  if (form.elements.cols) {
    params.board = { type: value('board_type'), cols: Number(value('cols')), rows: Number(value('rows')),
      square_size_mm: Number(value('square_size_mm')) };
    if (params.board.type === 'charuco') {
      params.board.marker_size_mm = Number(value('marker_size_mm'));
      params.board.aruco_dictionary = Number(value('aruco_dictionary'));
    }
  }
  if (type === 'relative_pose' && (value('cal_cam0') || value('cal_cam1'))) {
    params.calibrations = { cam0: value('cal_cam0'), cam1: value('cal_cam1') };
  }
  if ((type === 'stereo_reconstruct' || type === 'slam') && value('rig')) params.rig = value('rig');
  if (type === 'slam' && value('ground_truth')) params.ground_truth = value('ground_truth');
  if (type === 'slam' && form.elements.dense_map && form.elements.dense_map.checked) {
    params.dense_map = { voxel_m: Number(value('voxel_m')) };
  }
  if (RECORDING_CAMERAS[type] && value('recording')) {
    params.recording = value('recording');
    if (RECORDING_CAMERAS[type] === 1) params.topic = value('topic');
    else params.topics = { cam0: value('topic_cam0'), cam1: value('topic_cam1') };
  }
  const extra = value('extra');
  if (extra) Object.assign(params, JSON.parse(extra));
  return params;
}

async function renderForm(container, datasets, jobs, preselectedDataset, onSubmitted, preselectedType) {
  const succeeded = jobs.filter((j) => j.state === 'succeeded');
  const datasetNames = new Map(datasets.map((d) => [d.id, d.name]));
  const typeSelect = el('select', { name: 'type' },
    Object.entries(JOB_TYPES).map(([value, label]) => el('option', { value, selected: value === preselectedType }, `${value} — ${label}`)));
  const datasetSelect = el('select', { name: 'dataset', required: true },
    datasets.map((d) => el('option', { value: d.id, title: d.id, selected: d.id === preselectedDataset }, datasetLabel(d))));
  const specific = el('div.full.type-fields', { style: 'display:contents' });
  const messages = el('div.full');
  const form = el('form.grid#job-form', { onsubmit: submit },
    el('label', 'Job type'), typeSelect,
    el('label', 'Dataset'), datasets.length ? datasetSelect : el('span.muted', 'no dataset yet: create one first'),
    specific,
    el('label.full', 'Other parameters (JSON object, merged into params): ',
      el('textarea', { name: 'extra', placeholder: EXTRA_PLACEHOLDERS[typeSelect.value] || '{}' })),
    el('div.full', el('button.primary', { type: 'submit' }, 'Submit job')),
    messages);
  // The chosen dataset's .tum files, offered as the slam job's ground truth.
  const offerTrajectories = async () => {
    const list = form.querySelector('#tum-files');
    if (!list || !datasetSelect.value) return;
    try {
      const files = asList(await get(`/datasets/${encodeURIComponent(datasetSelect.value)}/images`), 'images');
      clear(list, files.filter((f) => /\.tum$/i.test(f.name)).map((f) => el('option', { value: f.name })));
    } catch (_) {
      clear(list);  // the suggestions are a help only
    }
  };
  // The chosen dataset's recordings, offered with their image topics to the job types that read
  // them; the fields stay hidden when it holds none.
  const offerRecordings = async () => {
    const fieldset = form.querySelector('fieldset.recording');
    if (!fieldset || !datasetSelect.value) return;
    let recordings = [];
    try {
      const dataset = await get(`/datasets/${encodeURIComponent(datasetSelect.value)}`);
      recordings = (dataset.recordings || []).filter((r) => Array.isArray(r.topics) &&
        r.topics.some((t) => IMAGE_TYPES.has(t.type)));
    } catch (_) {
      recordings = [];  // the offer is a help only
    }
    fieldset.hidden = recordings.length === 0;
    const select = fieldset.querySelector('select[name=recording]');
    const topics = fieldset.querySelector('.recording-topics');
    clear(select, el('option', { value: '' }, "the dataset's images"),
      recordings.map((r, i) => el('option', { value: r.name, selected: i === 0 }, r.name)));
    const showTopics = () => {
      const recording = recordings.find((r) => r.name === select.value);
      clear(topics, recording ? topicPickers(recording, RECORDING_CAMERAS[typeSelect.value]) : []);
    };
    select.onchange = showTopics;
    showTopics();
  };
  datasetSelect.addEventListener('change', offerTrajectories);
  datasetSelect.addEventListener('change', offerRecordings);
  const showType = () => {
    clear(specific, typeFields(typeSelect.value, succeeded, datasetNames));
    offerTrajectories();
    offerRecordings();
    form.elements.extra.placeholder = `e.g. ${EXTRA_PLACEHOLDERS[typeSelect.value] || '{}'}`;
    const boardType = form.elements.board_type;
    const charuco = specific.querySelector('.charuco');
    if (boardType && charuco) {
      const toggle = () => { charuco.hidden = boardType.value !== 'charuco'; };
      boardType.addEventListener('change', toggle);
      toggle();
    }
  };
  typeSelect.addEventListener('change', showType);
  showType();
  clear(container, el('h2', 'New job'), form);

  async function submit(e) {
    e.preventDefault();
    clear(messages);
    let params;
    try {
      params = paramsFromForm(typeSelect.value, form);
    } catch (err) {
      messages.append(errorBox(err, 'The extra parameters are not valid JSON'));
      return;
    }
    try {
      const job = await post('/jobs', { type: typeSelect.value, dataset: datasetSelect.value, params });
      messages.append(el('p.notice', 'Submitted ', el('a', { href: `#/jobs/${encodeURIComponent(job.id)}`, title: job.id, dataset: { jobId: job.id } },
        jobLabel(job, datasetNames)), '.'));
      onSubmitted(job);
    } catch (err) {
      messages.append(errorBox(err, 'The server refused the job'));
    }
  }
}

// ---- the live list ----------------------------------------------------------------------------

export function stateBadge(state) {
  return el(`span.state.state-${state}`, { dataset: { state } }, state);
}

// The bar: full when succeeded; red and stopped at the stage where a failed job stopped.
function progressCell(job) {
  const p = job.progress || {};
  if (job.state === 'succeeded') return progressBar(1, 'done');
  if (job.state === 'failed') return progressBar(p.fraction || 0, `failed${p.stage ? ` at ${p.stage}` : ''}`, true);
  if (TERMINAL.has(job.state)) return progressBar(p.fraction || 0, job.state);
  return progressBar(p.fraction || 0);
}

// The stage and message of the progress; in lists, a failed job's first reason and a link to
// the rest. "done" is shown only once the job has succeeded (with its summary).
function stageText(job, explainFailure = true) {
  const p = job.progress || {};
  if (job.state === 'failed' && explainFailure) {
    return [el('span.error-text', shortJobError(job.error)), ' ',
      el('a', { href: `#/jobs/${encodeURIComponent(job.id)}` }, 'why')];
  }
  const stage = p.stage === 'done' && job.state !== 'succeeded' ? '' : p.stage;
  return [stage ? el('strong', stage) : null, p.message ? ` ${p.message}` : ''];
}

// The failed job's whole error, one reason a line.
function errorCard(job) {
  const lines = errorLines(job.error && job.error.message);
  const p = job.progress || {};
  return el('div.error#job-error', { role: 'alert' },
    el('strong', `Why it failed${p.stage ? ` (at ${p.stage}, ${Math.round(100 * (p.fraction || 0))} %)` : ''}: `),
    explainJobError({ code: job.error && job.error.code, message: lines.length > 1 ? `${lines.length} problems` : lines[0] }),
    lines.length > 1 ? el('ul.error-lines', lines.map((line) => el('li', line))) : null);
}

function etaText(job) {
  const eta = job.progress && job.progress.eta_s;
  return job.state === 'running' && eta !== undefined && eta !== null ? formatDuration(eta) : '';
}

// Cancel / retry / delete buttons for one job; onChange runs after a successful action.
export function jobActions(job, onChange, errorTarget, editor) {
  const act = (label, cls, fn) => el(`button.${cls}`, {
    dataset: { action: label.toLowerCase() },
    onclick: async () => {
      try {
        await fn();
        onChange && onChange();
      } catch (err) {
        showError(errorTarget, err, `${label} failed`);
      }
    },
  }, label);
  const id = encodeURIComponent(job.id);
  return el('span.actions',
    TERMINAL.has(job.state) ? null : act('Cancel', 'warn', () => post(`/jobs/${id}/cancel`)),
    job.state === 'failed' || job.state === 'canceled' || job.state === 'cancelled'
      ? (editor ? el('button.plain', { dataset: { action: 'retry' }, onclick: () => editor(job) }, 'Retry…')
        : act('Retry', 'plain', () => post(`/jobs/${id}/retry`))) : null,
    job.state === 'running' ? null : act('Delete', 'danger', async () => {
      if (confirm(`Delete the ${job.type} job ${shortId(job.id)} and its results?`)) await del(`/jobs/${id}`);
    }));
}

function jobRow(job, refresh, errorTarget) {
  return el('tr', { dataset: { jobId: job.id, state: job.state } },
    el('td', el('a.mono', { href: `#/jobs/${encodeURIComponent(job.id)}`, title: job.id }, shortId(job.id))),
    el('td', job.type),
    el('td', { title: job.dataset ?? job.dataset_id ?? '' }, datasetLabel({ name: job.dataset_name }, job.dataset ?? job.dataset_id)),
    el('td', stateBadge(job.state), job.attempts > 1 ? el('span.muted', ` (attempt ${job.attempts})`) : null),
    el('td', { style: 'min-width:150px' }, progressCell(job)),
    el('td', stageText(job)),
    el('td.num', etaText(job)),
    el('td', formatTime(job.created_at)),
    el('td', jobActions(job, refresh, errorTarget, (j) => { location.hash = `#/jobs/${encodeURIComponent(j.id)}?retry=1`; })));
}

async function renderJobs(view, query) {
  const formCard = el('div.card');
  const stateFilter = el('select', { name: 'state' }, ['', 'queued', 'running', 'succeeded', 'failed', 'canceled']
    .map((s) => el('option', { value: s }, s || 'any state')));
  const typeFilter = el('select', { name: 'type' }, ['', ...Object.keys(JOB_TYPES)]
    .map((t) => el('option', { value: t }, t || 'any type')));
  const listErrors = el('div');
  const table = el('div.table-scroll#job-list');
  const listCard = el('div.card', el('h2', 'Jobs'), el('div.row', stateFilter, typeFilter), listErrors, table);
  clear(view, el('h1', 'Jobs'), formCard, listCard);

  let shown = '';  // the list as last drawn: redraw only on change, so buttons stay clickable
  const datasetNames = new Map();
  const refresh = async () => {
    const filter = new URLSearchParams({ limit: String(LIST_LIMIT) });
    if (stateFilter.value) filter.set('state', stateFilter.value);
    if (typeFilter.value) filter.set('type', typeFilter.value);
    try {
      const jobs = asList(await get(`/jobs?${filter}`), 'jobs');
      clear(listErrors);
      const snapshot = JSON.stringify(jobs);
      if (snapshot === shown) return jobs;
      shown = snapshot;
      for (const job of jobs) job.dataset_name = datasetNames.get(job.dataset ?? job.dataset_id);
      clear(table, jobs.length ? el('table',
        el('thead', el('tr', ['Job', 'Type', 'Dataset', 'State', 'Progress', 'Stage', 'ETA', 'Created', ''].map((h) => el('th', h)))),
        el('tbody', jobs.map((j) => jobRow(j, refresh, listErrors)))) : el('p.muted', 'No jobs.'));
      return jobs;
    } catch (err) {
      clear(listErrors, errorBox(err, 'Could not list the jobs'));
      return [];
    }
  };
  stateFilter.addEventListener('change', refresh);
  typeFilter.addEventListener('change', refresh);

  try {
    const [datasets, jobs] = await Promise.all([get('/datasets'), get(`/jobs?limit=${LIST_LIMIT}`)]);
    for (const d of asList(datasets, 'datasets')) datasetNames.set(d.id, d.name);
    await renderForm(formCard, asList(datasets, 'datasets'), asList(jobs, 'jobs'), query && query.get('dataset'), refresh,
      query && query.get('type'));
  } catch (err) {
    clear(formCard, errorBox(err, 'Could not load datasets and jobs'));
  }
  const events = subscribeJobEvents(() => refresh());
  let lastPoll = 0;
  const stop = poll(table, POLL_MS, async () => {
    if (events.live() && Date.now() - lastPoll < EVENT_POLL_MS) return;
    lastPoll = Date.now();
    await refresh();
  });
  return () => {
    stop();
    events.close();
  };
}

// ---- one job ----------------------------------------------------------------------------------

function statusCard(job, refresh, container, datasetName, summary) {
  const datasetId = job.dataset ?? job.dataset_id ?? '';
  return el('div.card#job-status', { dataset: { state: job.state } },
    el('div.row',
      el('div.grow',
        el('div.big', stateBadge(job.state), ' ', el('span.muted', job.type)),
        el('div', { style: 'margin:0.5rem 0' }, progressCell(job)),
        // A succeeded job's report states its figures here in the words of the report below.
        el('div#job-stage', summary && job.state === 'succeeded' ? [el('strong', 'done'), ` ${summary}`] : stageText(job, false)),
        etaText(job) ? el('div.muted', `about ${etaText(job)} left`) : null),
      el('dl.kv',
        el('dt', 'Job'), el('dd.mono', { title: job.id }, shortId(job.id)),
        el('dt', 'Dataset'), el('dd', el('a', { href: `#/datasets/${encodeURIComponent(datasetId)}`, title: datasetId },
          datasetLabel({ name: datasetName }, datasetId))),
        el('dt', 'Created'), el('dd', formatTime(job.created_at)),
        el('dt', 'Started'), el('dd', formatTime(job.started_at) || '–'),
        el('dt', 'Finished'), el('dd', formatTime(job.finished_at) || '–'),
        el('dt', 'Attempts'), el('dd', String(job.attempts ?? '–')))),
    job.state === 'failed' ? errorCard(job) : null,
    el('p', jobActions(job, refresh, container, (j) => retryEditor(container, j, refresh))),
    el('details', el('summary', 'Parameters'), el('pre.mono', JSON.stringify(job.params ?? {}, null, 2))));
}

// "Retry" offers to edit the parameters first: unchanged, the job runs again (POST retry);
// edited, a new job of the same type on the same dataset is submitted with them.
function retryEditor(container, job, refresh) {
  const old = container.querySelector('.retry-editor');
  if (old) old.remove();
  const original = JSON.stringify(job.params ?? {}, null, 2);
  const text = el('textarea', { name: 'retry_params', rows: Math.min(24, original.split('\n').length + 1) });
  text.value = original;
  const messages = el('div');
  const card = el('div.card.retry-editor',
    el('h2', 'Retry'), el('p', 'Edit the parameters if they caused the failure, then run the job again.'),
    text,
    el('p.row',
      el('button.primary', { type: 'button', dataset: { action: 'retry-run' }, onclick: run }, 'Run again'),
      el('button', { type: 'button', onclick: () => card.remove() }, 'Close')),
    messages);
  container.append(card);
  text.focus();
  text.setSelectionRange(0, 0);
  text.scrollTop = 0;

  async function run() {
    clear(messages);
    let params;
    try {
      params = JSON.parse(text.value);
    } catch (err) {
      messages.append(errorBox(err, 'The parameters are not valid JSON'));
      return;
    }
    try {
      if (JSON.stringify(params, null, 2) === original) {
        await post(`/jobs/${encodeURIComponent(job.id)}/retry`);
        card.remove();
        refresh();
      } else {
        const created = await post('/jobs', { type: job.type, dataset: job.dataset ?? job.dataset_id, params });
        location.hash = `#/jobs/${encodeURIComponent(created.id)}`;
      }
    } catch (err) {
      messages.append(errorBox(err, 'The server refused the job'));
    }
  }
}

// The report shown under a succeeded job, by type; `setSummary(text)` puts the report's
// one-line summary into the status card.
async function renderReport(container, job, setSummary) {
  const loaders = {
    calibration: () => import('./calibration_report.js'),
    relative_pose: () => import('./stereo_report.js'),
    stereo_reconstruct: () => import('./viewer.js'),
    slam: () => import('./viewer.js'),
  };
  const loader = loaders[job.type];
  if (!loader) return null;
  const module = await loader();
  return module.renderJobReport(container, job, setSummary);
}

async function renderJob(view, id, openRetry = false) {
  const status = el('div');
  const report = el('div#report');
  const artifacts = el('div.card#artifacts');
  const title = el('h1#job-title', `Job ${shortId(id)}`);
  clear(view, el('p', el('a', { href: '#/jobs' }, '← all jobs')), title, status, report, artifacts);
  let shownState = null;
  let shownJob = '';
  let reportCleanup = null;
  let datasetName = null;
  let summary = null;
  const refresh = async () => {
    let job;
    try {
      job = await get(`/jobs/${encodeURIComponent(id)}`);
    } catch (err) {
      clear(status, errorBox(err, 'Could not load the job'));
      return;
    }
    if (datasetName === null) {
      const datasetId = job.dataset ?? job.dataset_id;
      datasetName = await get(`/datasets/${encodeURIComponent(datasetId)}`).then((d) => d.name || '', () => '');
      title.textContent = `${JOB_TYPES[job.type] || job.type}: “${datasetName || shortId(datasetId)}” · ${shortId(id)}`;
      title.title = `job ${id}`;
    }
    const snapshot = JSON.stringify(job);
    if (snapshot !== shownJob) clear(status, statusCard(job, refresh, status, datasetName, summary));
    if (openRetry && !shownJob && (job.state === 'failed' || job.state === 'canceled')) retryEditor(status, job, refresh);
    shownJob = snapshot;
    if (job.state === shownState) return;
    shownState = job.state;
    if (reportCleanup) reportCleanup();
    reportCleanup = null;
    clear(report);
    clear(artifacts);
    if (job.state === 'running' && isLiveSlam(job)) reportCleanup = renderLiveReport(report, job);
    if (job.state === 'succeeded') {
      try {
        reportCleanup = await renderReport(report, job, (text) => {
          summary = text;
          const stage = status.querySelector('#job-stage');
          if (stage) clear(stage, el('strong', 'done'), ` ${text}`);
        });
      } catch (err) {
        clear(report, errorBox(err, 'Could not show the report'));
      }
    }
    if (TERMINAL.has(job.state)) await renderArtifacts(artifacts, job.id, job.type);
  };
  const events = subscribeJobEvents(() => {
    if (!TERMINAL.has(shownState)) refresh();
  }, id);
  let lastPoll = 0;
  const stop = poll(status, POLL_MS, async () => {
    if (TERMINAL.has(shownState) || (events.live() && Date.now() - lastPoll < EVENT_POLL_MS)) return;
    lastPoll = Date.now();
    await refresh();
  });
  return () => {
    stop();
    events.close();
    if (reportCleanup) reportCleanup();
  };
}
