// The page's router: one module per page, chosen by the location hash.
//   #/datasets            datasets: create, list
//   #/datasets/ID         one dataset: upload (drag and drop, resume), thumbnails
//   #/jobs[?dataset=ID]   jobs: a form per job type, the live list
//   #/jobs/ID             one job: status, its report (calibration, stereo, 3D), artifacts
//   #/viewer[/JOB_ID]     the 3D viewer (a job's PLY and trajectory, or a local PLY file)

import { get, getToken, setToken } from './api.js';
import { clear, el, errorBox } from './ui.js';

const pages = {
  datasets: () => import('./datasets.js'),
  jobs: () => import('./jobs.js'),
  viewer: () => import('./viewer.js'),
};

let cleanup = null;
let generation = 0;

async function route() {
  const app = document.getElementById('app');
  const [path, query = ''] = (location.hash || '#/datasets').split('?');
  const [, page = 'datasets', id = '', ...rest] = path.split('/');
  const thisGeneration = ++generation;
  if (cleanup) {
    try {
      cleanup();
    } catch (e) {
      console.error(e);
    }
    cleanup = null;
  }
  for (const link of document.querySelectorAll('[data-nav]')) {
    link.classList.toggle('active', link.dataset.nav === page);
  }
  const loader = pages[page];
  if (!loader) {
    clear(app, el('p', `No page "${page}".`));
    return;
  }
  clear(app, el('p.muted', 'Loading…'));
  try {
    const module = await loader();
    if (thisGeneration !== generation) return;  // the user navigated on meanwhile
    const view = el('section.page', { dataset: { page } });
    clear(app, view);
    cleanup = (await module.render(view, decodeURIComponent(id),
      new URLSearchParams(query), rest.map(decodeURIComponent))) || null;
  } catch (e) {
    console.error(e);
    if (thisGeneration === generation) clear(app, errorBox(e, 'This page could not be shown'));
  }
}

async function showHealth() {
  const badge = document.getElementById('health');
  try {
    const health = await get('/health');
    badge.textContent = (health && health.status) || 'ok';
    badge.className = 'health ok';
  } catch (e) {
    badge.textContent = 'server unreachable';
    badge.className = 'health bad';
    badge.title = e.message;
  }
}

// The server asked for a bearer token (omnirig serve --token): ask for it in the top bar.
function askForToken() {
  const holder = document.getElementById('auth');
  if (holder.childElementCount) return;
  const input = el('input', { type: 'password', placeholder: 'API token', size: 18, value: getToken() });
  const form = el('form', {
    onsubmit: (e) => {
      e.preventDefault();
      setToken(input.value.trim());
      clear(holder);
      showHealth();
      route();
    },
  }, el('span', 'This server needs a token: '), input, el('button', { type: 'submit' }, 'Use'));
  clear(holder, form);
}

window.addEventListener('omnirig:unauthorized', askForToken);
window.addEventListener('hashchange', route);
route();
showHealth();
