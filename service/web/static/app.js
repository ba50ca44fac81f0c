// The motionx page: a form that uploads a trial and starts a job or a library on it
// (newwalk.js), lists of motions, jobs and libraries, a job's live progress curve, a
// library's grid of cells (status and λ reached as a heat map; a cell's clip in the 3D
// preview), a motion's 3D preview (on the input's own rig when the export has it), GRF plot,
// plausibility report and downloads in every export format. Plain ES modules, no framework,
// no build step.
//
// What the forms offer comes from the API itself: the target axes from GET /axes, the upload
// fields, the tutor's characters and fps, the step control and the export formats from the
// OpenAPI document (GET /openapi.json).
//
// Every API call carries the key (X-API-Key). The key comes from the input box or from the
// URL fragment (#key=...), and is remembered in localStorage. Authenticated images are
// fetched as blobs and shown through object URLs. A running job or library is followed
// through its Server-Sent Events (GET /jobs/{id}/events, /libraries/{id}/events), read
// with fetch() since the browser's EventSource cannot send the key in a header.
//
// Test hook: window.motionx.state (flags such as progressPoints, previewReady, previewRig,
// grfLoaded, libraryCells, cellKey, uploadStatus, startStatus, downloadStatus).

import { drawProgress } from './progress.js';
import { initNewWalk } from './newwalk.js';

const KEY_STORAGE = 'motionx.apiKey';
const LIST_POLL_MS = 3000;
const STREAM_RETRY_MS = 1000; // a broken event stream is opened again after this
const TERMINAL = new Set(['succeeded', 'failed', 'canceled', 'impasse']); // service.models.TERMINAL
const PREVIEW_UNAVAILABLE = '3D preview unavailable: run npm ci in service/web';

const state = {
  keyStatus: 'none', // none | ok | invalid
  motions: [],
  jobs: [],
  jobId: null,
  jobStatus: null,
  progressPoints: 0, // solves drawn in the progress canvas
  jobMotions: [],
  motionId: null,
  previewReady: false,
  previewError: null,
  grfLoaded: false,
  grfError: null,
  residualsLoaded: false,
  residualsError: null,
  filmstripLoaded: false,
  filmstripError: null,
  validation: null,
  previewRig: null, // the preview's skeleton: source (the input's own rig) | character (the motion's)
  previewObjects: 0, // three.js objects of the previewed model
  environmentReached: null, // the followed job's environment at λ reached (axis -> value)
  formats: [], // the export formats (GET /motions/{id}?format=…, from the OpenAPI document)
  exports: null, // the selected motion's downloads (GET /motions/{id}/exports): formats, on_rig, rig, source
  downloadStatus: null, // ok | error: the last download
  libraries: [],
  libraryId: null,
  libraryStatus: null,
  libraryCells: 0, // cells drawn in the grid
  libraryDone: 0,
  cellKey: null, // the cell whose clip is previewed
  simulationStatus: null, // the selected motion's simulation: none | queued | running | succeeded | failed | canceled
  simulationReport: null, // its report (report.json) once succeeded
  simulationShown: false, // the simulated walk is in the 3D preview beside the motion
  simulationLoaded: false, // the simulation's plot is shown
  simulationError: null,
  errors: [],
};
window.motionx = { state, viewer: null, selectJob, selectMotion, selectLibrary, previewVariants, simulate };

const $ = (id) => document.getElementById(id);
let apiKey = '';
let jobToken = 0; // bumped on every selection, so late answers for a previous one are dropped
let motionToken = 0;
let libraryToken = 0;
let keyToken = 0; // bumped when the key changes: list answers fetched with an earlier key are dropped
let lastProgress = [];
const streams = { job: null, library: null }; // the AbortController of each open event stream
let viewerPromise = null;
const objectUrls = new Map(); // <img> id -> object URL to revoke
const rigOf = new Map(); // motion id -> the preview variant that worked (source | character)
const canceling = new Set(); // ids of the jobs and libraries whose cancel the API accepted
let previewLastOf = null; // a job started from the form: its last λ optimum is previewed when it ends
let newWalk = null; // the form (newwalk.js)
let previewDone = Promise.resolve(); // the selected motion's preview (the simulated walk is shown beside it)
const SIMULATION_POLL_MS = 1000;

// ---------------------------------------------------------------- helpers

/** A DOM element: h('li', {class: 'x', onclick: f}, child, 'text', ...). */
function h(tag, attrs = {}, ...children) {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === undefined || v === null || v === false) continue;
    if (k.startsWith('on')) el.addEventListener(k.slice(2), v);
    else if (k === 'class') el.className = v;
    else el.setAttribute(k, v === true ? '' : v);
  }
  el.append(...children.flat().filter((c) => c !== null && c !== undefined && c !== false));
  return el;
}

/** <dl> items: one <div> per (term, value), so each pair stays together in the facts' grid. */
const factItems = (pairs) => pairs.map(([k, v]) => h('div', {}, h('dt', {}, k), h('dd', {}, v)));
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));
const shortId = (id) => (id ? id.slice(0, 10) : '');
const fmt = (x, digits = 3) => (typeof x === 'number' && Number.isFinite(x) ? String(+x.toPrecision(digits)) : '–');
const sci = (x) => (typeof x === 'number' && Number.isFinite(x) ? (x === 0 ? '0' : x.toExponential(1)) : '–');
const clock = (iso) => (iso ? new Date(iso).toLocaleString([], { dateStyle: 'short', timeStyle: 'medium' }) : '');

// the homotopy axes (GET /axes, the solver's registry): names, units, words, defaults; like every
// API call it needs the key (without one the forms are built once a key is given)
const AXES = [];

async function loadAxes(key) {
  try {
    const res = await fetch('/axes', { headers: key ? { 'X-API-Key': key } : {} });
    if (res.ok) AXES.splice(0, AXES.length, ...(await res.json()).axes);  // in place: the form holds this array
  } catch (err) {
    noteError('axes', err);
  }
}

// from the OpenAPI document: the upload form's fields, the tutor, the step control, the export formats
let SCHEMA = null;

async function loadSchema() {
  try {
    const res = await fetch('/openapi.json');
    if (!res.ok) throw new Error(`GET /openapi.json: ${res.status}`);
    const doc = await res.json();
    const get = doc.paths['/motions/{motion_id}'].get;
    const format = get.parameters.find((p) => p.name === 'format');
    SCHEMA = {
      upload: doc.paths['/motions'].post.requestBody.content['multipart/form-data'].schema,
      tutor: doc.components.schemas.TutorIn,
      control: doc.components.schemas.StepControlIn,
      formats: format.schema.enum,
    };
    state.formats = SCHEMA.formats.slice();
  } catch (err) {
    noteError('schema', err);
  }
}

const axisOf = (name) => AXES.find((a) => a.name === name);
const axisChanges = (a, v) => v !== null && v !== undefined && (a.default === null || v !== a.default);

function targetText(t = {}) {
  const parts = [];
  for (const a of AXES) if (axisChanges(a, t[a.name])) parts.push(a.words.replace('{}', t[a.name]));
  return parts.join(', ') || '–';
}

function noteError(where, err) {
  const msg = `${where}: ${err && err.message ? err.message : err}`;
  state.errors.push(msg);
  console.warn(msg);
}

// ---------------------------------------------------------------- API

class ApiError extends Error {
  constructor(status, detail) {
    super(detail);
    this.status = status;
  }
}

/**
 * fetch() with the API key; `as` is json | blob | arrayBuffer | response. `json`: a JSON body;
 * `body`: any other body (FormData: multipart). Problem details become ApiError.
 */
async function api(path, { as = 'json', method = 'GET', json, body } = {}) {
  if (!apiKey) throw new ApiError(401, 'no API key: enter one above');
  const headers = { 'X-API-Key': apiKey };
  if (json !== undefined) {
    headers['Content-Type'] = 'application/json';
    body = JSON.stringify(json);
  }
  const res = await fetch(path, { method, headers, body });
  if (!res.ok) {
    const detail = await problemDetail(res);
    if (res.status === 401) setKeyStatus('invalid', detail);
    throw new ApiError(res.status, detail);
  }
  setKeyStatus('ok');
  return as === 'response' ? res : res[as]();
}

/** The `detail` of a problem answer, or its status line when it is not JSON. */
async function problemDetail(res) {
  try {
    const problem = await res.json();
    if (problem && problem.detail) return problem.detail;
  } catch { /* not JSON */ }
  return `${res.status} ${res.statusText}`;
}

/**
 * Reads the Server-Sent Events of `path` with the key, calling onEvent(name, data, id) for
 * each, until the stream ends (resolves true when an `end` event came) or `kind`'s stream is
 * replaced (a new selection aborts the previous one).
 */
async function followEvents(kind, path, onEvent) {
  if (!apiKey) throw new ApiError(401, 'no API key');
  if (streams[kind]) streams[kind].abort();
  const controller = new AbortController();
  streams[kind] = controller;
  let ended = false;
  try {
    const res = await fetch(path, { headers: { 'X-API-Key': apiKey, Accept: 'text/event-stream' },
      signal: controller.signal, cache: 'no-store' });
    if (!res.ok) throw new ApiError(res.status, await problemDetail(res));
    const reader = res.body.pipeThrough(new TextDecoderStream()).getReader();
    let buffer = '';
    for (;;) {
      const { value, done } = await reader.read();
      if (done) break;
      buffer = (buffer + value).replace(/\r\n/g, '\n');
      let cut;
      while ((cut = buffer.indexOf('\n\n')) >= 0) {
        const block = buffer.slice(0, cut);
        buffer = buffer.slice(cut + 2);
        let name = 'message', id = null;
        const data = [];
        for (const line of block.split('\n')) {
          const colon = line.indexOf(':');
          if (colon === 0) continue; // a comment (the server's keep-alive ping)
          const field = colon < 0 ? line : line.slice(0, colon);
          const text = colon < 0 ? '' : line.slice(colon + 1).replace(/^ /, '');
          if (field === 'event') name = text;
          else if (field === 'data') data.push(text);
          else if (field === 'id') id = text;
        }
        if (!data.length) continue;
        if (name === 'end') ended = true;
        onEvent(name, JSON.parse(data.join('\n')), id);
      }
    }
  } catch (err) {
    if (controller.signal.aborted) return false;
    throw err;
  } finally {
    if (streams[kind] === controller) streams[kind] = null;
  }
  return ended;
}

/** The newest `n` items of a paginated list (the API lists oldest first), newest first. */
async function newest(path, n = 200) {
  let page = await api(`${path}?limit=${n}`);
  if (page.total > n) page = await api(`${path}?offset=${page.total - n}&limit=${n}`);
  return page.items.slice().reverse();
}

// ---------------------------------------------------------------- API key

function setKeyStatus(status, detail = '') {
  state.keyStatus = status;
  const el = $('key-status');
  el.className = `status ${status === 'ok' ? 'ok' : status === 'invalid' ? 'bad' : ''}`;
  el.textContent = status === 'ok' ? 'connected' : status === 'invalid' ? detail || 'invalid API key' : 'no key';
}

function useKey(key) {
  apiKey = key.trim();
  if (apiKey) localStorage.setItem(KEY_STORAGE, apiKey);
  else localStorage.removeItem(KEY_STORAGE);
  $('key-input').value = apiKey;
  // another key sees other motions and jobs: start afresh
  jobToken += 1;
  motionToken += 1;
  libraryToken += 1;
  keyToken += 1;
  for (const c of Object.values(streams)) if (c) c.abort();
  Object.assign(state, { motions: [], jobs: [], libraries: [], jobId: null, jobStatus: null, motionId: null,
    libraryId: null, libraryStatus: null, cellKey: null });
  $('job-panel').hidden = $('motion-panel').hidden = $('library-panel').hidden = true;
  $('new-walk-key').hidden = Boolean(apiKey);
  previewLastOf = null;
  if (newWalk) newWalk.reset();
  setKeyStatus('none');
  refreshLists();
  // the forms were built without the axes (no key at start): build them again with this key
  if (apiKey && !AXES.length && newWalk) loadAxes(apiKey).then(() => { if (AXES.length) newWalk.renderAxes(); });
}

function keyFromFragment() {
  const params = new URLSearchParams(location.hash.slice(1));
  const key = params.get('key');
  if (key === null) return null;
  params.delete('key'); // keep the key out of the address bar, bookmarks and screenshots
  const rest = params.toString();
  history.replaceState(null, '', location.pathname + location.search + (rest ? `#${rest}` : ''));
  return key;
}

// ---------------------------------------------------------------- lists

async function refreshLists() {
  const token = keyToken;
  try {
    const [motions, jobs, libraries] = await Promise.all([newest('/motions'), newest('/jobs'), newest('/libraries', 50)]);
    if (token !== keyToken) return;
    state.motions = motions;
    state.jobs = jobs;
    state.libraries = libraries;
  } catch (err) {
    if (token !== keyToken) return;
    if (!(err instanceof ApiError && err.status === 401)) noteError('lists', err);
    else state.motions = state.jobs = state.libraries = [];
  }
  renderMotionList();
  renderJobList();
  renderLibraryList();
}

/** What an empty list says: nothing there yet, or no access. */
function emptyText(what) {
  if (state.keyStatus === 'ok') return `no ${what} yet`;
  return state.keyStatus === 'invalid' ? 'this API key is not valid' : `enter an API key to see your ${what}`;
}

function listButton(id, selected, title, badge, sub, onclick) {
  return h('li', {}, h('button', { type: 'button', class: selected ? 'selected' : '', 'data-id': id, onclick },
    h('span', { class: 'title' }, title), badge, h('span', { class: 'sub' }, sub)));
}

function renderJobList() {
  const ul = $('job-list');
  ul.replaceChildren(...state.jobs.map((j) => listButton(
    j.id,
    j.id === state.jobId,
    targetText(j.target),
    h('span', { class: `badge ${j.status}` }, j.status),
    `λ ${fmt(j.lam_reached)} · ${j.steps} steps · ${shortId(j.id)} · ${clock(j.created_at)}`,
    () => selectJob(j.id),
  )));
  if (!state.jobs.length) ul.append(h('li', { class: 'empty' }, emptyText('jobs')));
  ul.dataset.count = state.jobs.length;
}

function renderMotionList() {
  const showSteps = $('show-steps').checked;
  const motions = state.motions.filter((m) => showSteps || m.kind !== 'step');
  const ul = $('motion-list');
  ul.replaceChildren(...motions.map((m) => listButton(
    m.id,
    m.id === state.motionId,
    m.name || (m.kind === 'step' ? `λ = ${fmt(m.lam)} (step ${m.step})` : m.kind),
    plausibleBadge(m.plausible),
    `${m.kind} · ${m.character} · ${m.frames} frames at ${fmt(m.fps)} fps · ${shortId(m.id)}`,
    () => selectMotion(m.id),
  )));
  if (!motions.length) ul.append(h('li', { class: 'empty' }, emptyText('motions')));
  ul.dataset.count = motions.length;
  if (newWalk) newWalk.renderSources();
}

function naturalBadge(natural) {
  if (natural === null || natural === undefined) return h('span', { class: 'badge' }, 'unchecked');
  return h('span', { class: `badge ${natural ? 'yes' : 'no'}` }, natural ? 'natural' : 'not natural');
}

function plausibleBadge(plausible) {
  if (plausible === null || plausible === undefined) return h('span', { class: 'badge' }, 'unchecked');
  return h('span', { class: `badge ${plausible ? 'yes' : 'no'}` }, plausible ? 'plausible' : 'not plausible');
}

// ---------------------------------------------------------------- a job

/** Shows a job and follows it while it runs; `previewLast`: preview its last λ optimum when it ends. */
async function selectJob(id, { previewLast = false } = {}) {
  const token = ++jobToken;
  Object.assign(state, { jobId: id, jobStatus: null, progressPoints: 0, jobMotions: [], environmentReached: null });
  lastProgress = [];
  previewLastOf = previewLast ? id : null;
  $('job-panel').hidden = false;
  $('job-id').textContent = id;
  $('job-facts').replaceChildren();
  $('job-motions').replaceChildren(h('li', { class: 'empty' }, 'none yet'));
  renderJobList();
  drawProgress($('progress-canvas'), []);

  // the job as it is; while it runs, its event stream (which starts with every progress point
  // and λ optimum so far); once more when the stream ends, or after a pause if it broke off
  while (token === jobToken) {
    try {
      const job = await api(`/jobs/${id}`);
      if (token !== jobToken) return;
      renderJob(job);
      await loadJobMotions(id, token);
      if (job.terminal) {
        if (previewLastOf === id && token === jobToken && state.jobMotions.length) {
          previewLastOf = null;
          await selectMotion(state.jobMotions[state.jobMotions.length - 1].id);
        }
        return;
      }
      if (await followJob(id, token)) continue; // it ended: read the job's final state at once
    } catch (err) {
      if (token !== jobToken) return;
      $('job-facts').replaceChildren(...factItems([['error', err.message]]));
      if (err instanceof ApiError && err.status < 500) return;
    }
    if (token === jobToken) await sleep(STREAM_RETRY_MS);
  }
}

/** Follows a running job's events: status (the job without its curve), progress points (of
 * the current attempt: the id is attempt:seq) and λ optima, redrawn as they come. */
async function followJob(id, token) {
  let attempt = null, job = null;
  const curve = [];
  const motions = [];
  return followEvents('job', `/jobs/${id}/events`, (name, data, eventId) => {
    if (token !== jobToken) return;
    if (name === 'progress') {
      const a = eventId ? eventId.split(':')[0] : attempt;
      if (a !== attempt) curve.length = 0; // a new attempt draws its own curve
      attempt = a;
      curve.push(data);
      if (job) renderJob({ ...job, progress: curve });
    } else if (name === 'status') {
      job = { ...data, terminal: TERMINAL.has(data.status) };
      renderJob({ ...job, progress: curve });
    } else if (name === 'motion') {
      motions.push(data);
      showJobMotions(motions);
    }
  });
}

function renderJob(job) {
  state.jobStatus = job.status;
  const status = $('job-status');
  status.className = `badge ${job.status}`;
  status.textContent = job.status;
  cancelButton($('job-cancel'), job, 'Cancel job');
  const facts = [
    ['target', targetText(job.target)],
    ['λ reached', fmt(job.lam_reached, 4)],
    ['steps / solves', `${job.steps} / ${job.solves}`],
    ['attempt', `${job.attempts} of ${job.max_attempts}`],
    ['method', `${job.control.method ?? '–'}, Δ0 = ${job.control.delta0 ?? '–'}`],
    ['started', clock(job.started_at) || '–'],
  ];
  state.environmentReached = environmentReached(job.progress);
  if (state.environmentReached) facts.splice(2, 0, ['environment reached', environmentText(job.target, state.environmentReached)]);
  if (job.message) facts.push(['message', job.message]);
  $('job-facts').replaceChildren(...factItems(facts));
  lastProgress = job.progress;
  state.progressPoints = drawProgress($('progress-canvas'), lastProgress);
  // keep the list's badge in step with the panel
  const listed = state.jobs.find((j) => j.id === job.id);
  if (listed && (listed.status !== job.status || listed.lam_reached !== job.lam_reached)) {
    Object.assign(listed, job);
    renderJobList();
  }
}

/** The environment (axis -> value) of the last accepted solve at the λ reached. */
function environmentReached(points) {
  const at = points.filter((p) => p.phase === 'extrapolate' && p.accepted && p.lam === p.lam_reached);
  const last = at[at.length - 1];
  return last && last.environment && Object.keys(last.environment).length ? last.environment : null;
}

/** The reached values of the axes the target changes, in the axes' words (slope 2.5°, μ=0.8). */
function environmentText(target = {}, env) {
  const parts = AXES.filter((a) => axisChanges(a, target[a.name]) && typeof env[a.name] === 'number')
    .map((a) => a.words.replace('{}', fmt(env[a.name], 4)));
  return parts.join(', ') || '–';
}

async function loadJobMotions(id, token) {
  const items = [];
  let url = `/jobs/${id}/motions?limit=200`;
  while (url) {
    const page = await api(url);
    items.push(...page.items);
    url = page.next;
  }
  if (token !== jobToken) return;
  showJobMotions(items);
}

function showJobMotions(items) {
  state.jobMotions = items;
  const ol = $('job-motions');
  ol.replaceChildren(...items.map((m) => h('li', {}, h('button', {
    type: 'button',
    class: m.id === state.motionId ? 'selected' : '',
    'data-id': m.id,
    title: `step ${m.step}, ${m.id}`,
    onclick: () => selectMotion(m.id),
  }, `λ = ${fmt(m.lam)} `, plausibleMark(m.plausible)))));
  if (!items.length) ol.append(h('li', { class: 'empty' }, 'none yet'));
}

function plausibleMark(plausible) {
  if (plausible === null || plausible === undefined) return '';
  return h('span', { class: plausible ? 'mark-yes' : 'mark-no', title: plausible ? 'plausible' : 'not plausible' },
    plausible ? '✓' : '✗');
}

/** A job's or library's cancel button: hidden once it has ended, "Canceling…" once asked. */
function cancelButton(button, run, label) {
  const asked = Boolean(run.cancel_requested) || canceling.has(run.id); // events may predate the request
  button.hidden = run.terminal;
  button.disabled = asked;
  button.textContent = asked ? 'Canceling…' : label;
}

/** POST …/cancel from the panel's button; what the API answers is shown at once (a 409 in the facts). */
async function cancel(kind) {
  const id = kind === 'job' ? state.jobId : state.libraryId;
  if (!id) return;
  const button = $(`${kind}-cancel`);
  button.disabled = true;
  try {
    const run = await api(`/${kind === 'job' ? 'jobs' : 'libraries'}/${id}/cancel`, { method: 'POST' });
    canceling.add(id);
    if (id === (kind === 'job' ? state.jobId : state.libraryId)) cancelButton(button, run, button.textContent);
  } catch (err) {
    if (!(err instanceof ApiError)) noteError('cancel', err); // the API's answer (a 409: it had ended) is shown
    button.disabled = false;
    if (id === (kind === 'job' ? state.jobId : state.libraryId)) {
      $(`${kind}-facts`).append(h('div', {}, h('dt', {}, 'cancel'), h('dd', { class: 'bad' }, err.message)));
    }
  }
}

// ---------------------------------------------------------------- a library

const axisLabel = (axis) => (axisOf(axis) ? axisOf(axis).label : axis);
const axisValue = (axis, v) => (axisOf(axis) ? axisOf(axis).words.replace('{}', v) : `${axis} ${v}`);

function libraryTitle(lib) {
  if (lib.grid) return Object.entries(lib.grid).map(([a, vs]) => `${axisLabel(a)} ×${vs.length}`).join(' · ');
  return `${lib.progress.cells} targets`;
}

function renderLibraryList() {
  const ul = $('library-list');
  ul.replaceChildren(...state.libraries.map((lib) => listButton(
    lib.id,
    lib.id === state.libraryId,
    `${libraryTitle(lib)} (${lib.progress.cells} cells)`,
    h('span', { class: `badge ${lib.status}` }, lib.status),
    `${lib.progress.done}/${lib.progress.cells} done · ${shortId(lib.id)} · ${clock(lib.created_at)}`,
    () => selectLibrary(lib.id),
  )));
  if (!state.libraries.length) ul.append(h('li', { class: 'empty' }, emptyText('libraries')));
  ul.dataset.count = state.libraries.length;
}

async function selectLibrary(id) {
  const token = ++libraryToken;
  Object.assign(state, { libraryId: id, libraryStatus: null, libraryCells: 0, libraryDone: 0, cellKey: null });
  $('library-panel').hidden = false;
  $('library-id').textContent = id;
  $('library-facts').replaceChildren();
  $('library-grid').replaceChildren();
  renderLibraryList();
  // as for a job: the library, then its event stream while it runs (cells and overall progress)
  while (token === libraryToken) {
    try {
      const lib = await api(`/libraries/${id}`);
      if (token !== libraryToken) return;
      renderLibrary(lib);
      if (lib.terminal) return;
      const ended = await followEvents('library', `/libraries/${id}/events`, (name, data) => {
        if (token !== libraryToken) return;
        if (name === 'cell') {
          const i = lib.cells.findIndex((c) => c.key === data.key);
          if (i >= 0) lib.cells[i] = data;
        } else if (name === 'status') {
          Object.assign(lib, data, { terminal: TERMINAL.has(data.status) });
        } else {
          return;
        }
        renderLibrary(lib);
      });
      if (ended) continue; // read the library's final state at once
    } catch (err) {
      if (token !== libraryToken) return;
      $('library-facts').replaceChildren(...factItems([['error', err.message]]));
      if (err instanceof ApiError && err.status < 500) return;
    }
    if (token === libraryToken) await sleep(STREAM_RETRY_MS);
  }
}

function cellButton(cell) {
  const lam = cell.lam_reached;
  const attrs = {
    type: 'button',
    class: `${cell.status}${cell.key === state.cellKey ? ' selected' : ''}`,
    'data-key': cell.key,
    'data-status': cell.status,
    title: `${cell.key}: ${cell.status}, λ reached ${fmt(lam, 4)}, ${cell.solves} solves${cell.message ? ` — ${cell.message}` : ''}`,
    onclick: () => selectCell(cell),
  };
  const what = cell.status === 'impasse' ? `impasse λ ${fmt(lam, 2)}` : cell.status === 'succeeded' ? 'λ 1'
    : cell.status === 'running' ? `λ ${fmt(lam, 2)}` : cell.status;
  // realism of the cell's clip: ✓ plausible, ✗ not, nothing when unchecked or no clip yet
  const mark = cell.plausible === true ? ' ✓' : cell.plausible === false ? ' ✗' : '';
  const button = h('button', attrs, what + mark);
  if (cell.status === 'running') { // shade: λ reached (CSSOM, which the page's style-src allows)
    const pct = Math.round(100 * lam);
    button.style.background = `linear-gradient(90deg, #9cc3e8 ${pct}%, #eef1f4 ${pct}%)`;
  }
  return button;
}

function renderLibrary(lib) {
  state.libraryStatus = lib.status;
  const status = $('library-status');
  status.className = `badge ${lib.status}`;
  status.textContent = lib.status;
  cancelButton($('library-cancel'), lib, 'Cancel library');
  const p = lib.progress;
  const times = lib.cells.map((c) => c.wall_time_s).filter((t) => typeof t === 'number');
  const facts = [
    ['cells', `${p.done} of ${p.cells} done`],
    ['succeeded / impasse', `${p.succeeded} / ${p.impasse}`],
    ['failed / canceled', `${p.failed} / ${p.canceled}`],
    ['running / queued', `${p.running} / ${p.queued}`],
    ['overall', `${fmt(100 * p.fraction, 3)} %`],
    ['time per cell', times.length ? `${fmt(times.reduce((a, b) => a + b, 0) / times.length)} s` : '–'],
  ];
  $('library-facts').replaceChildren(...factItems(facts));
  $('library-bar-fill').style.width = `${(100 * p.fraction).toFixed(1)}%`;

  // the grid: rows = first axis, columns = second (one column for a single axis); a list of
  // targets, or a third axis, is a table of one cell per row
  const axes = lib.axes || [];
  const table = $('library-grid');
  const rows = [];
  if (lib.grid && axes.length <= 2) {
    const [ra, ca] = axes;
    const rv = lib.grid[ra] || [null];
    const cv = ca ? lib.grid[ca] : [null];
    const at = new Map(lib.cells.map((c) => [`${c.parameters[ra]}|${ca ? c.parameters[ca] : ''}`, c]));
    rows.push(h('tr', {}, h('th', {}, ca ? `${axisLabel(ra)} \\ ${axisLabel(ca)}` : ''),
      ...cv.map((v) => h('th', {}, ca ? axisValue(ca, v) : ''))));
    for (const r of rv) {
      rows.push(h('tr', {}, h('th', {}, axisValue(ra, r)), ...cv.map((c) => {
        const cell = at.get(`${r}|${ca ? c : ''}`);
        return h('td', {}, cell ? cellButton(cell) : '');
      })));
    }
  } else {
    rows.push(h('tr', {}, h('th', {}, 'target'), h('th', {}, 'cell')));
    for (const cell of lib.cells) {
      rows.push(h('tr', {}, h('th', {}, Object.entries(cell.parameters).map(([a, v]) => axisValue(a, v)).join(', ')),
        h('td', {}, cellButton(cell))));
    }
  }
  table.replaceChildren(h('tbody', {}, rows));
  state.libraryCells = table.querySelectorAll('button[data-key]').length;
  state.libraryDone = p.done;
  const listed = state.libraries.find((l) => l.id === lib.id);
  if (listed && (listed.status !== lib.status || listed.progress.done !== p.done)) {
    Object.assign(listed, lib);
    renderLibraryList();
  }
}

/** A cell's clip (its last realistic λ optimum) in the motion panel's 3D preview. */
async function selectCell(cell) {
  state.cellKey = cell.key;
  document.querySelectorAll('#library-grid button').forEach((b) => b.classList.toggle('selected', b.dataset.key === cell.key));
  try {
    const items = [];
    let url = `/jobs/${cell.job_id}/motions?limit=200`;
    while (url) {
      const page = await api(url);
      items.push(...page.items);
      url = page.next;
    }
    const clip = items.find((m) => m.id === cell.clip_motion_id) || items.filter((m) => m.plausible !== false).pop();
    if (!clip) {
      noteError('cell', new Error(`cell ${cell.key} has no motion yet`));
      return;
    }
    state.jobMotions = items;
    await selectMotion(clip.id);
  } catch (err) {
    noteError('cell', err);
  }
}

async function downloadLibrary(what) {
  const id = state.libraryId;
  if (!id) return;
  try {
    const blob = await api(what === 'glb' ? `/libraries/${id}/library.glb` : `/libraries/${id}/manifest`, { as: 'blob' });
    saveBlob(blob, what === 'glb' ? `${id}.glb` : `${id}.manifest.json`);
  } catch (err) {
    noteError('download', err);
    $('library-facts').append(h('div', {}, h('dt', {}, 'download'), h('dd', { class: 'bad' }, `failed: ${err.message}`)));
  }
}

// ---------------------------------------------------------------- a motion

async function selectMotion(id) {
  const token = ++motionToken;
  Object.assign(state, {
    motionId: id, previewReady: false, previewError: null, grfLoaded: false, grfError: null,
    residualsLoaded: false, residualsError: null, filmstripLoaded: false, filmstripError: null, validation: null,
    previewRig: null, previewObjects: 0, downloadStatus: null, exports: null, simulationStatus: null, simulationReport: null,
    simulationShown: false, simulationLoaded: false, simulationError: null,
  });
  $('motion-panel').hidden = false;
  $('download-status').textContent = '';
  $('download-rig-box').hidden = true;
  $('download-rig-none').hidden = true;
  renderDownloadButtons(null);
  $('viewer-rig').textContent = '';
  $('motion-id').textContent = id;
  $('motion-facts').textContent = '';
  $('validation').replaceChildren(h('tbody', {}, h('tr', {}, h('td', {}, 'loading…'))));
  renderMotionList();
  document.querySelectorAll('#job-motions button').forEach((b) => b.classList.toggle('selected', b.dataset.id === id));

  const meta = state.motions.find((m) => m.id === id) || state.jobMotions.find((m) => m.id === id);
  if (meta) {
    $('motion-facts').textContent = [meta.kind, meta.character, `${meta.frames} frames at ${fmt(meta.fps)} fps`,
      `${fmt(meta.duration_s)} s`, meta.lam !== null ? `λ = ${fmt(meta.lam)} (step ${meta.step})` : null,
      meta.job_id ? `job ${shortId(meta.job_id)}` : null].filter(Boolean).join(' · ');
  }
  const validation = loadValidation(id, token);
  const exports = loadExports(id, token);
  previewDone = loadPreview(id, token, validation, exports);
  await Promise.all([
    previewDone,
    exports,
    loadSimulation(id, token),
    loadImage('grf', `/motions/${id}/plots/grf.png`, token),
    loadImage('residuals', `/motions/${id}/plots/residuals.png`, token),
    loadImage('filmstrip', `/motions/${id}/plots/filmstrip.png`, token),
    validation,
  ]);
}

async function loadValidation(id, token) {
  try {
    const report = await api(`/motions/${id}/validation`);
    if (token !== motionToken) return null;
    state.validation = report;
    renderValidation(report);
    return report;
  } catch (err) {
    if (token === motionToken) {
      $('validation').replaceChildren(h('tbody', {}, h('tr', {}, h('td', { class: 'check-no' }, err.message))));
    }
    return null;
  }
}

/** A figure as the report table shows it: scientific notation for the residual-sized ones. */
const figure = (x) => (typeof x === 'number' && x !== 0 && Math.abs(x) < 1e-2 ? sci(x) : fmt(x));

/** The report's sections in order: its `sections` list, or (a report without one) every
 * top-level object with `checks`. */
function reportSections(r) {
  if (Array.isArray(r.sections)) return r.sections.filter((s) => r[s.name] && r[s.name].checks);
  return Object.keys(r).filter((k) => r[k] && typeof r[k] === 'object' && r[k].checks)
    .map((name) => ({ name, title: name.replaceAll('_', ' ') }));
}

/** Every registered check section of the report (solver.checks), each check with its value,
 * limit, the captured walk's own figure where the check has one, and its verdict; a section the
 * page has never heard of renders the same way. Warnings (!) do not fail. */
function renderValidation(r) {
  const rows = [
    h('tr', { class: 'verdict' }, h('th', {}, 'plausible'),
      h('td', { colspan: 3 }, plausibleBadge(r.plausible === undefined ? null : r.plausible))),
    h('tr', { class: 'verdict' }, h('th', {}, 'natural'),
      h('td', { colspan: 3 }, naturalBadge(r.natural === undefined ? null : r.natural))),
  ];
  if (r.error) rows.push(h('tr', { class: 'problems' }, h('td', { colspan: 4 }, r.error)));
  for (const sec of reportSections(r)) {
    const checks = Object.entries(r[sec.name].checks).filter(([, c]) => c.applies !== false);
    if (!checks.length) continue;
    rows.push(h('tr', { class: 'section', 'data-section': sec.name }, h('th', {}, sec.title || sec.name),
      h('th', {}, 'value'), h('th', {}, 'limit'), h('th', {}, '')));
    for (const [name, c] of checks) {
      const warn = c.severity === 'warning';
      const capture = c.capture !== undefined && c.capture !== null ? ` (capture ${figure(c.capture)})` : '';
      const value = c.value === null ? (c.missing || '–') : `${figure(c.value)}${capture}`;
      const unit = c.unit ? ` (${c.unit})` : '';
      const title = [c.what, c.source ? `Source: ${c.source}` : ''].filter(Boolean).join('. ');
      rows.push(h('tr', { 'data-check': name }, h('th', {}, `${name.replaceAll('_', ' ')}${unit}`),
        h('td', { class: 'num' }, value), h('td', { class: 'num' }, `${c.bound === 'min' ? '≥' : '≤'} ${figure(c.limit)}`),
        h('td', { class: c.passed ? 'check-yes' : (warn ? '' : 'check-no'), title },
          c.passed ? '✓' : (warn ? '!' : '✗'))));
    }
  }
  const row = (label, value) => h('tr', {}, h('th', {}, label), h('td', { class: 'num' }, value), h('td'), h('td'));
  const env = r.environment || {};
  if (env.gravity) rows.push(row('gravity (m/s²)', env.gravity.map((g) => fmt(g)).join(', ')));
  if (env.friction !== undefined) rows.push(row('friction', fmt(env.friction)));
  if (r.problems && r.problems.length) rows.push(h('tr', { class: 'problems' }, h('td', { colspan: 4 }, r.problems.join('; '))));
  $('validation').replaceChildren(h('tbody', {}, rows));
}

function viewer() {
  // three.js is imported on demand: without node_modules the rest of the page keeps working
  viewerPromise ??= import('./preview.js').then(({ Viewer }) => {
    const v = new Viewer($('viewer-canvas'));
    window.motionx.viewer = v;
    return v;
  });
  return viewerPromise;
}

function viewerMessage(text) {
  const el = $('viewer-message');
  el.hidden = !text;
  el.textContent = text || '';
}

async function loadPreview(id, token, validation, exportsLoaded) {
  viewerMessage('');
  let v;
  try {
    v = await viewer();
  } catch (err) {
    state.previewError = PREVIEW_UNAVAILABLE;
    document.querySelectorAll('.viewer > :not(.message)').forEach((el) => { el.hidden = true; });
    viewerMessage(PREVIEW_UNAVAILABLE);
    noteError('preview', err);
    return;
  }
  try {
    const [{ glb, rig }, report, exports] = await Promise.all([previewGlb(id), validation, exportsLoaded]);
    if (token !== motionToken) return;
    const gravity = report && report.environment ? report.environment.gravity : undefined;
    const treads = report && report.environment ? report.environment.treads : undefined; // stairs
    const shown = await v.show(glb, { gravity, treads });
    if (token !== motionToken) return;
    const meta = motionMeta(id);
    state.previewRig = rig;
    state.previewObjects = shown.objects;
    $('viewer-rig').textContent = rig !== 'source' ? `on the ${meta ? meta.character : "motion's"} character`
      : exports && exports.rig === 'opensim' ? "on its OpenSim model's bodies" : "on the input's own rig";
    state.previewReady = true;
  } catch (err) {
    if (token !== motionToken) return;
    state.previewError = err.message;
    viewerMessage(`No 3D preview: ${err.message}`);
  }
}

/**
 * The GLB queries a motion's preview tries, in order (the first the API answers is shown):
 * the motion on the input's own rig (GET /motions/{id}?format=glb&rig=source: a motion made
 * from a BVH, DeepMimic or glTF trial carries that rig in its provenance; one from an OpenSim
 * trial is shown on its model's bodies), then the motion on
 * its own character (HalfBoy or the full body). A 4xx moves on to the next.
 */
function previewVariants() {
  return [{ rig: 'source', query: 'format=glb&rig=source' }, { rig: 'character', query: 'format=glb' }];
}

/** The motion's GLB for the preview and the variant it is ({glb, rig}); remembered per motion. */
async function previewGlb(id) {
  const variants = previewVariants();
  const known = rigOf.get(id);
  const order = known ? [variants.find((v) => v.rig === known), ...variants.filter((v) => v.rig !== known)] : variants;
  let last = null;
  for (const variant of order) {
    try {
      const glb = await api(`/motions/${id}?${variant.query}`, { as: 'arrayBuffer' });
      rigOf.set(id, variant.rig);
      return { glb, rig: variant.rig };
    } catch (err) {
      if (!(err instanceof ApiError && err.status >= 400 && err.status < 500 && err.status !== 401)) throw err;
      last = err;
    }
  }
  throw last;
}

const motionMeta = (id) => state.motions.find((m) => m.id === id) || state.jobMotions.find((m) => m.id === id);

/** An authenticated PNG into <img id="{name}-img">, or the API's reason in {name}-message. */
async function loadImage(name, path, token) {
  const img = $(`${name}-img`);
  const message = $(`${name}-message`);
  img.hidden = true;
  message.hidden = true;
  try {
    const blob = await api(path, { as: 'blob' });
    if (token !== motionToken) return;
    const url = URL.createObjectURL(blob);
    if (objectUrls.has(name)) URL.revokeObjectURL(objectUrls.get(name));
    objectUrls.set(name, url);
    await new Promise((resolve, reject) => {
      img.onload = resolve;
      img.onerror = () => reject(new Error('not a valid image'));
      img.src = url;
    });
    if (token !== motionToken) return;
    img.hidden = false;
    state[`${name}Loaded`] = true;
  } catch (err) {
    if (token !== motionToken) return;
    state[`${name}Error`] = err.message;
    message.textContent = `No plot: ${err.message}`;
    message.hidden = false;
  }
}

// ---------------------------------------------------------------- a motion's simulation in MuJoCo

/** The selected motion's latest simulation (GET /motions/{id}/simulation), followed while it runs. */
async function loadSimulation(id, token) {
  renderSimulation(null);
  let sim;
  try {
    sim = await api(`/motions/${id}/simulation`);
  } catch (err) {
    if (token !== motionToken) return;
    if (err instanceof ApiError && err.status === 404) {
      state.simulationStatus = 'none';
      $('simulation-status').textContent = 'not simulated yet';
      return;
    }
    state.simulationError = err.message;
    $('simulation-status').textContent = `simulation: ${err.message}`;
    return;
  }
  if (token === motionToken) await followSimulation(id, token, sim);
}

/** Starts a simulation of the selected motion (POST /motions/{id}/simulation) and follows it. */
async function simulate(cycles) {
  const id = state.motionId;
  const token = motionToken;
  if (!id) return;
  $('simulation-start').disabled = true;
  $('simulation-status').textContent = 'starting…';
  state.simulationError = null;
  try {
    const sim = await api(`/motions/${id}/simulation`, { method: 'POST', json: { cycles } });
    if (token === motionToken) await followSimulation(id, token, sim);
  } catch (err) {
    if (token !== motionToken) return;
    state.simulationError = err.message;
    state.simulationStatus = state.simulationStatus || 'none';
    $('simulation-status').textContent = `not started: ${err.message}`;
  } finally {
    if (token === motionToken) $('simulation-start').disabled = ['queued', 'running'].includes(state.simulationStatus);
  }
}

/** Polls a simulation until it ends (or another motion is selected), then shows what it produced. */
async function followSimulation(id, token, sim) {
  while (token === motionToken) {
    renderSimulation(sim);
    if (sim.terminal) break;
    await sleep(SIMULATION_POLL_MS);
    if (token !== motionToken) return;
    try {
      sim = await api(`/motions/${id}/simulation`);
    } catch (err) {
      noteError('simulation', err);
      await sleep(SIMULATION_POLL_MS);
    }
  }
  if (token !== motionToken || sim.status !== 'succeeded') return;
  await Promise.all([
    loadImage('simulation', sim.links['simulation.png'], token),
    showSimulated(sim, token),
  ]);
}

/** The simulated walk (simulated.glb) beside the motion in the 3D preview. */
async function showSimulated(sim, token) {
  try {
    await previewDone;
    if (token !== motionToken || !state.previewReady) return;
    const [v, glb] = await Promise.all([viewer(), api(sim.links['simulated.glb'], { as: 'arrayBuffer' })]);
    if (token !== motionToken) return;
    const start = sim.report ? sim.report.start_reference_time_s : 0;
    await v.showCompanion(glb, { start });
    if (token !== motionToken) return;
    state.simulationShown = true;
    $('viewer-rig').textContent += ' · blue: simulated in MuJoCo';
  } catch (err) {
    if (token !== motionToken) return;
    state.simulationError = err.message;
    viewerMessage(`No simulated walk: ${err.message}`);
  }
}

function renderSimulation(sim) {
  state.simulationStatus = sim ? sim.status : null;
  state.simulationReport = sim && sim.status === 'succeeded' ? sim.report : null;
  const active = Boolean(sim) && !sim.terminal;
  $('simulation-start').disabled = active;
  const table = $('simulation-report');
  const downloads = $('simulation-downloads');
  if (!sim) {
    $('simulation-status').textContent = '';
    table.hidden = downloads.hidden = true;
    $('simulation-img').hidden = $('simulation-message').hidden = true;
    return;
  }
  const since = sim.started_at ? ` since ${clock(sim.started_at)}` : '';
  $('simulation-status').textContent = {
    queued: `queued (${sim.cycles} cycles)…`,
    running: `simulating ${sim.cycles} cycles${since}…`,
    succeeded: `done: ${sim.message}`,
  }[sim.status] || `${sim.status}: ${sim.message}`;
  const r = state.simulationReport;
  table.hidden = !r;
  downloads.hidden = !r;
  if (!r) return;
  const drift = (r.drift_per_cycle || []).at(-1);
  const row = (label, value) => h('tr', {}, h('th', {}, label), h('td', { class: 'num' }, value));
  table.replaceChildren(h('tbody', {},
    row('cycles walked', `${fmt(r.cycles_walked)} of ${r.cycles_requested ?? sim.cycles}`),
    ...(r.resync ? [row('cycles completed from the reference state (root residual RMS, body weight)',
      `${r.resync.completed} of ${r.resync.cycles} (${fmt(r.resync.residual_root_wrench_rms_bw)})`)] : []),
    row('fell', r.fell ? `yes, at ${fmt(r.fall && r.fall.time_s)} s (${(r.fall && r.fall.reason) || ''})` : 'no'),
    row('joint tracking RMS (°)', fmt(r.joint_tracking_rms_deg)),
    row('foot force RMS (body weight)', fmt(r.foot_force_rms_bw)),
    row('peak torque / inverse dynamics (max)', fmt(r.peak_torque_ratio_max)),
    row('drift after the last cycle (m)', drift ? fmt(drift.position_m) : '–'),
    row('real-time factor (simulated s / wall s)', fmt(r.realtime_factor)),
  ));
  downloads.replaceChildren('Download: ', ...Object.keys(sim.files).map((name) => h('button', {
    type: 'button',
    onclick: async () => {
      try {
        saveBlob(await api(sim.links[name], { as: 'blob' }), `${sim.motion_id}.${name}`);
      } catch (err) {
        noteError('download', err);
      }
    },
  }, name)), ' ');
}

/** A blob saved as a file (an <a download> on an object URL: the API wants the key, so no plain link). */
function saveBlob(blob, name) {
  const a = h('a', { href: URL.createObjectURL(blob), download: name });
  a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 10_000);
}

/** What a format's button says (a format this table does not know shows its name). */
const FORMAT_LABELS = { json: 'JSON clip', gltf: 'glTF (.glb)', glb: 'glTF (.glb)', bvh: 'BVH', deepmimic: 'DeepMimic',
  opensim: 'OpenSim (zip)', motion: 'motion file' };
/** Formats that write the same file as another (one button per distinct file). */
const FORMAT_ALIASES = { glb: 'gltf' };
/** The words for the input's own skeleton, by its format (the rig box's label). */
const RIG_WORDS = { bvh: 'its BVH skeleton', gltf: 'its glTF character', deepmimic: 'its DeepMimic character' };

/** A file name for an export, from its media type: .glb, .gltf, .zip, .FORMAT.json, .bvh … */
function exportFileName(id, format, mediaType, onRig) {
  const mt = (mediaType || '').split(';')[0].trim();
  const ext = { 'model/gltf-binary': 'glb', 'model/gltf+json': 'gltf', 'application/zip': 'zip' }[mt]
    ?? (mt === 'application/json' ? (format === 'json' ? 'clip.json' : `${format}.json`) : format);
  return `${id}${onRig ? '.rig' : ''}.${ext}`;
}

/**
 * One button per distinct file the selected motion can be downloaded as: its formats from
 * GET /motions/{id}/exports (no DeepMimic or OpenSim for a motion that cannot have them), else
 * the API's enum without aliases (glb is gltf's file); the motion file last. The box "on the
 * input's own rig" is shown when the motion carries the input's skeleton, and says which; when
 * it carries none, a note says the downloads are on the motion's own character.
 */
function renderDownloadButtons(exports) {
  const formats = exports ? [...exports.formats, 'motion']
    : state.formats.filter((f) => !FORMAT_ALIASES[f] || !state.formats.includes(FORMAT_ALIASES[f]));
  $('download-buttons').replaceChildren(...formats.map((f) => h('button', {
    type: 'button', 'data-format': f, onclick: () => download(f),
  }, FORMAT_LABELS[f] ?? f)));
  if (!formats.length) $('download-buttons').append(h('span', { class: 'hint' }, 'formats unavailable'));
  const onRig = Boolean(exports && exports.on_rig.length);
  $('download-rig-box').hidden = !onRig;
  $('download-rig-words').textContent = onRig ? RIG_WORDS[exports.rig] || exports.rig : '';
  const none = $('download-rig-none');
  none.hidden = !exports || onRig;
  none.textContent = exports && !onRig ? `on the ${motionMeta(state.motionId)?.character || "motion's"} character: `
    + `the trial${exports.source ? ` (${exports.source})` : ''} has no skeleton of its own to write it on` : '';
}

/** The selected motion's downloads (GET /motions/{id}/exports), then its buttons. */
async function loadExports(id, token) {
  try {
    const exports = await api(`/motions/${id}/exports`);
    if (token !== motionToken) return;
    state.exports = exports;
    renderDownloadButtons(exports);
    return exports;
  } catch (err) {
    if (token === motionToken && !(err instanceof ApiError)) noteError('exports', err);
    return null;
  }
}

/** The exporter options typed beside the buttons (NAME=VALUE separated by spaces, commas or &) as a query string. */
function exportOptions() {
  const query = new URLSearchParams();
  for (const part of $('download-options').value.split(/[\s,&]+/).filter(Boolean)) {
    const eq = part.indexOf('=');
    if (eq <= 0) throw new Error(`exporter option ${JSON.stringify(part)} is not NAME=VALUE`);
    query.append(part.slice(0, eq), part.slice(eq + 1));
  }
  const text = query.toString();
  return text ? `&${text}` : '';
}

/**
 * Downloads the selected motion as `format`. With "on the input's own rig" ticked (shown when
 * the motion has that rig) it asks for rig=source first; a format that cannot write the motion
 * there (4xx) gives the motion on its own character, and the status line says why.
 */
async function download(format) {
  const id = state.motionId;
  if (!id) return;
  const status = $('download-status');
  const exports = state.exports;
  const rigTicked = !$('download-rig-box').hidden && $('download-rig').checked && format !== 'motion';
  const wantRig = rigTicked && exports !== null && exports.on_rig.includes(format);
  const fail = (message) => {
    state.downloadStatus = 'error';
    status.className = 'status-line bad';
    status.textContent = `${FORMAT_LABELS[format] ?? format}: ${message}`;
  };
  let options;
  try {
    options = format === 'motion' ? '' : exportOptions();
  } catch (err) {
    fail(err.message);
    return;
  }
  state.downloadStatus = 'busy';
  status.className = 'status-line busy';
  status.textContent = `preparing ${FORMAT_LABELS[format] ?? format}…`;
  let note = rigTicked && !wantRig ? ` on the motion's own character (${FORMAT_LABELS[format] ?? format} is not written `
    + `on ${RIG_WORDS[exports?.rig] || "the input's rig"})` : '';
  if (!rigTicked && exports && !exports.on_rig.length && format !== 'motion') {
    note = ` on the motion's own character (the trial has no skeleton of its own)`;
  }
  try {
    let res = null;
    if (wantRig) {
      try {
        res = await api(`/motions/${id}?format=${format}&rig=source${options}`, { as: 'response' });
      } catch (err) {
        if (!(err instanceof ApiError && err.status >= 400 && err.status < 500 && err.status !== 401)) throw err;
        note = ` on the motion's own character (not on the input's rig: ${err.message})`;
      }
    }
    const onRig = res !== null;
    res ??= await api(`/motions/${id}?format=${format}${options}`, { as: 'response' });
    const blob = await res.blob();
    const name = exportFileName(id, format, res.headers.get('content-type'), onRig);
    saveBlob(blob, name);
    if (id !== state.motionId) return;
    state.downloadStatus = 'ok';
    status.className = 'status-line ok';
    status.textContent = `downloaded ${name}${onRig ? " (on the input's own rig)" : note}`;
  } catch (err) {
    if (!(err instanceof ApiError)) noteError('download', err); // the API's refusals are shown, not errors of the page
    if (id === state.motionId) fail(err.message);
  }
}

// ---------------------------------------------------------------- start

function start() {
  $('key-form').addEventListener('submit', (e) => {
    e.preventDefault();
    useKey($('key-input').value);
  });
  $('key-forget').addEventListener('click', () => useKey(''));
  $('show-steps').addEventListener('change', renderMotionList);
  $('job-cancel').addEventListener('click', () => cancel('job'));
  $('library-cancel').addEventListener('click', () => cancel('library'));
  $('library-glb').addEventListener('click', () => downloadLibrary('glb'));
  $('library-manifest').addEventListener('click', () => downloadLibrary('manifest'));
  $('viewer-play').addEventListener('click', async () => {
    const v = await viewer();
    v.setPlaying(!v.playing);
    $('viewer-play').textContent = v.playing ? 'Pause' : 'Play';
  });
  $('simulation-form').addEventListener('submit', (e) => {
    e.preventDefault();
    const cycles = Number($('simulation-cycles').value);
    simulate(cycles);
  });
  $('viewer-follow').addEventListener('change', async (e) => (await viewer()).setFollow(e.target.checked));
  new ResizeObserver(() => {
    if (state.jobId) drawProgress($('progress-canvas'), lastProgress);
  }).observe($('progress-canvas'));
  window.addEventListener('hashchange', () => {
    const key = keyFromFragment();
    if (key !== null) useKey(key);
  });

  const key = keyFromFragment() ?? localStorage.getItem(KEY_STORAGE) ?? '';
  $('new-walk-key').hidden = Boolean(key);
  // the target words and grid labels come from GET /axes, the forms and the export formats from
  // the OpenAPI document; a key entered meanwhile is kept
  const before = keyToken;
  Promise.all([loadAxes(key), loadSchema()]).finally(() => {
    renderDownloadButtons(state.exports);
    newWalk = initNewWalk({
      api, ApiError, h, state, axes: AXES, schema: SCHEMA, noteError, refreshLists, selectMotion,
      started: (kind, id) => (kind === 'library' ? selectLibrary(id) : selectJob(id, { previewLast: true })),
      uploaded: (motion) => {
        if (!state.motions.some((m) => m.id === motion.id)) state.motions.unshift(motion);
        renderMotionList();
      },
    });
    if (keyToken === before) useKey(key);
    else if (apiKey && !AXES.length) loadAxes(apiKey).then(() => { if (AXES.length) newWalk.renderAxes(); });
  });
  setInterval(() => {
    if (!document.hidden) refreshLists();
  }, LIST_POLL_MS);
}

start();
