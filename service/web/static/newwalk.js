// The "New walk" form of the page: upload a captured walk (drag and drop or the file input,
// several files per trial), then start an extrapolation job (one target) or a library (a
// grid of targets) on it, with the tutor's character and fps and the step control.
//
// Everything it offers comes from the API: the target axes, their units and ranges from
// GET /axes; the importer options, the tutor's characters and fps, and the step control from
// the OpenAPI document (the multipart body of POST /motions, TutorIn, StepControlIn). The
// subject's mass field is shown and marked required up front when the files are of a format
// that never states it (BVH, glTF), and whenever the API answers that the trial needs it (a 422
// naming the form field, shown as it is): the API stays the judge of what a trial needs.

/** File suffixes of formats that never state the subject's mass. */
const NO_MASS_SUFFIXES = ['.bvh', '.glb', '.gltf'];
/** Fields of the upload with controls of their own (the others are importer options). */
const OWN_FIELDS = new Set(['files', 'name']);
/** A 422 of POST /motions names the form field the trial needs: "… send the form field 'mass' (kg)". */
const ASKED_FIELD = /form field '(\w+)'/;
const MAX_GRID_CELLS = 125; // service.schemas.LibraryIn

/**
 * Builds the form and wires it. `ctx`: api, ApiError, h (the page's helpers), state (the
 * page's state: the form adds its flags), axes (GET /axes), schema (from the OpenAPI
 * document), noteError, refreshLists, selectMotion, uploaded(motion) and started(kind, id).
 * Returns {renderSources, reset}.
 */
export function initNewWalk(ctx) {
  const { api, ApiError, h, state, axes, schema, noteError } = ctx;
  const $ = (id) => document.getElementById(id);
  let files = []; // the trial's File objects, distinct names
  const asked = new Map(); // field -> the API's reason, for the files selected now
  let sourcesShown = '';

  Object.assign(state, {
    trialFiles: [], // names of the files selected
    massRequired: false,
    uploadStatus: null, // busy | ok | error
    uploadedId: null,
    startStatus: null, // busy | ok | error
    startedId: null,
  });

  const status = (el, kind, text) => {
    el.className = `status-line ${kind === 'error' ? 'bad' : kind}`;
    el.textContent = text;
  };

  // ------------------------------------------------------------ the trial's files

  const uploadFields = (schema && schema.upload && schema.upload.properties) || {};
  const filesDoc = uploadFields.files && uploadFields.files.description;
  $('trial-formats').textContent = filesDoc ? `(${filesDoc})` : '';

  function addFiles(list) {
    for (const f of list) {
      files = files.filter((g) => g.name !== f.name); // the server wants distinct names: the newest wins
      files.push(f);
    }
    asked.clear();
    renderFiles();
  }

  function renderFiles() {
    state.trialFiles = files.map((f) => f.name);
    $('trial-list').replaceChildren(...files.map((f) => h('li', {},
      h('span', { class: 'title' }, f.name), h('span', { class: 'hint' }, sizeText(f.size)),
      h('button', { type: 'button', class: 'quiet', title: `remove ${f.name}`, 'aria-label': `remove ${f.name}`,
        onclick: () => { files = files.filter((g) => g !== f); asked.clear(); renderFiles(); } }, '×'))));
    placeFields();
  }

  const input = $('trial-files');
  input.addEventListener('change', () => {
    addFiles(Array.from(input.files));
    input.value = ''; // choosing the same file again is a change again
  });
  const zone = $('drop-zone');
  for (const type of ['dragenter', 'dragover']) {
    zone.addEventListener(type, (e) => {
      e.preventDefault();
      zone.classList.add('over');
    });
  }
  zone.addEventListener('dragleave', () => zone.classList.remove('over'));
  zone.addEventListener('drop', (e) => {
    e.preventDefault();
    zone.classList.remove('over');
    if (e.dataTransfer && e.dataTransfer.files.length) addFiles(Array.from(e.dataTransfer.files));
  });

  // ------------------------------------------------------------ importer options and the mass

  const optionNames = Object.keys(uploadFields).filter((k) => !OWN_FIELDS.has(k));
  // the mass first: it is the one most trials need
  optionNames.sort((a, b) => (a === 'mass' ? -1 : b === 'mass' ? 1 : 0));
  $('option-fields').replaceChildren(...optionNames.map((k) => optionField(k, uploadFields[k])));
  if (!optionNames.length) $('option-fields').append(h('p', { class: 'hint' }, 'no importer options (the API schema did not load)'));

  function optionField(name, prop) {
    let control;
    if (prop.type === 'boolean' || prop.enum) {
      const values = prop.type === 'boolean' ? ['true', 'false'] : prop.enum;
      control = h('select', {}, h('option', { value: '' }, 'default'), ...values.map((v) => h('option', { value: v }, v)));
    } else if (prop.type === 'number' || prop.type === 'integer') {
      control = h('input', { type: 'number', step: 'any', min: prop.minimum, max: prop.maximum });
    } else {
      control = h('input', { type: 'text', maxlength: prop.maxLength, spellcheck: 'false' });
    }
    control.id = `opt-${name}`;
    control.name = name;
    return h('label', { class: 'field', id: `field-${name}` },
      h('span', { class: 'name' }, name === 'mass' ? 'subject mass (kg)' : name.replaceAll('_', ' ')), control,
      prop.description ? h('small', { class: 'hint' }, prop.description) : null);
  }

  /** The mass is needed up front (every file of a format that never states it) or because the API said so. */
  function massNeeded() {
    if (asked.has('mass')) return true;
    return files.length > 0 && files.every((f) => NO_MASS_SUFFIXES.some((s) => f.name.toLowerCase().endsWith(s)));
  }

  /** The mass beside the name (required) when it is needed, else first among the options; a field the
   * API asked for is marked and its options opened. */
  function placeFields() {
    const need = massNeeded();
    state.massRequired = need;
    const field = $('field-mass');
    if (field) {
      $('opt-mass').required = need;
      field.classList.toggle('needed', need);
      if (need) $('mass-slot').append(field);
      else $('option-fields').prepend(field);
    }
    const why = $('mass-why');
    why.hidden = !need;
    why.textContent = asked.has('mass') ? "The API needs the subject's mass (kg) for these files: they do not state it."
      : "These files (BVH, glTF) do not state the subject's mass: enter it in kg.";
    for (const name of optionNames) {
      const f = $(`field-${name}`);
      if (name !== 'mass') f.classList.toggle('needed', asked.has(name));
    }
    if ([...asked.keys()].some((k) => k !== 'mass')) $('trial-options').open = true;
  }

  // ------------------------------------------------------------ upload

  /** No files, no name, every option back to its default. */
  function clearTrial() {
    files = [];
    asked.clear();
    $('trial-name').value = '';
    for (const name of optionNames) $(`opt-${name}`).value = '';
    renderFiles();
  }

  async function upload(e) {
    e.preventDefault();
    const out = $('upload-status');
    if (!files.length) {
      state.uploadStatus = 'error';
      status(out, 'error', "choose or drop the trial's files first");
      return;
    }
    const form = new FormData();
    for (const f of files) form.append('files', f, f.name);
    const label = $('trial-name').value.trim();
    if (label) form.append('name', label);
    for (const name of optionNames) {
      const control = $(`opt-${name}`);
      if (control.validity && control.validity.badInput) {
        state.uploadStatus = 'error';
        status(out, 'error', `${name}: not a number`);
        control.focus();
        return;
      }
      if (control.value.trim()) form.append(name, control.value.trim());
    }
    const button = $('upload-button');
    button.disabled = true;
    state.uploadStatus = 'busy';
    status(out, 'busy', `uploading ${files.length} file${files.length > 1 ? 's' : ''}; the server imports the trial…`);
    $('upload-facts').hidden = true;
    try {
      const motion = await api('/motions', { method: 'POST', body: form });
      state.uploadedId = motion.id;
      state.uploadStatus = 'ok';
      status(out, 'ok', `uploaded: ${motion.kind} ${motion.id}`);
      showUpload(motion);
      clearTrial(); // the next trial starts from an empty form (its facts stay shown)
      ctx.uploaded(motion);
      $('source-select').value = motion.id;
      renderSourceNote();
      ctx.refreshLists();
    } catch (err) {
      state.uploadStatus = 'error';
      const m = err instanceof ApiError && err.status === 422 ? ASKED_FIELD.exec(err.message) : null;
      if (m && $(`field-${m[1]}`)) {
        asked.set(m[1], err.message);
        placeFields();
        $(`opt-${m[1]}`).focus();
      }
      // a trial the API refused for what the files are: they go, so the next files are a new trial (not a mix
      // of formats with these); a trial that only needs a field (the mass) keeps them for the retry
      const keep = Boolean(m && $(`field-${m[1]}`));
      if (!keep && files.length) {
        files = [];
        asked.clear();
        renderFiles();
      }
      status(out, 'error', keep ? err.message : `${err.message} (the files were cleared: choose the trial's files again)`);
      if (!(err instanceof ApiError)) noteError('upload', err);
    } finally {
      button.disabled = false;
    }
  }

  /** What the API made of the upload: the motion, and for a trial what its input looks like. */
  function showUpload(m) {
    const i = m.input || {};
    const facts = [
      ['motion', `${m.name || m.kind} (${m.kind}, ${m.character})`],
      ['frames', `${m.frames} at ${fmtNum(m.fps)} fps, ${fmtNum(m.duration_s)} s`],
    ];
    if (i.format) facts.push(['format', i.format]);
    if (typeof i.mass_kg === 'number') facts.push(['mass', `${fmtNum(i.mass_kg)} kg${i.mass_from ? ` (${i.mass_from})` : ''}`]);
    if (typeof i.mass_implied_kg === 'number') facts.push(['mass the plates imply', `${fmtNum(i.mass_implied_kg)} kg`]);
    if (i.mass_warning) facts.push(['warning', i.mass_warning]);
    if (i.stances) {
      facts.push(['stances', Object.entries(i.stances).map(([side, s]) => `${side} ${Array.isArray(s) ? s.length : s}`).join(', ')]);
    }
    for (const k of ['marker_fit_error_mm', 'landmark_fit_error_mm']) {
      if (typeof i[k] === 'number') facts.push([k.replace('_mm', '').replaceAll('_', ' '), `${fmtNum(i[k])} mm`]);
    }
    if (i.stance_error) facts.push(['stances', i.stance_error]);
    const dl = $('upload-facts');
    dl.replaceChildren(...facts.map(([k, v]) => h('div', {}, h('dt', {}, k), h('dd', {}, v))),
      h('div', {}, h('dt', {}, 'preview'), h('dd', {}, h('button', { type: 'button', class: 'quiet',
        onclick: () => ctx.selectMotion(m.id) }, 'show it walking'))));
    dl.hidden = false;
  }

  // ------------------------------------------------------------ source, tutor, target, control

  const tutorProps = Object.fromEntries(Object.entries((schema && schema.tutor && schema.tutor.properties) || {})
    .map(([k, p]) => [k, plain(p)]));
  const character = $('tutor-character');
  const chars = (tutorProps.character && tutorProps.character.enum) || [];
  // an optional character (null: the service's default) is offered as such, first
  const serviceDefault = tutorProps.character && tutorProps.character.nullable;
  character.replaceChildren(...(serviceDefault ? [h('option', { value: '' }, "the service's default")] : []),
    ...chars.map((c) => h('option', { value: c }, c)));
  if (tutorProps.character && tutorProps.character.default) character.value = tutorProps.character.default;
  const fps = $('tutor-fps');
  if (tutorProps.fps) {
    Object.assign(fps, { min: tutorProps.fps.minimum, max: tutorProps.fps.maximum, value: tutorProps.fps.default ?? '',
      placeholder: tutorProps.fps.default == null ? "the character's" : '' });
    fps.title = tutorProps.fps.description || '';
  }

  function renderSources() {
    const sel = $('source-select');
    const items = state.motions.filter((m) => m.kind !== 'step');
    const shown = items.map((m) => `${m.id}|${m.name}`).join(',');
    if (shown === sourcesShown && sel.options.length) return; // unchanged: an open list stays open
    sourcesShown = shown;
    const keep = sel.value;
    // nothing is chosen for the user: the walk just uploaded, or the one picked in the list
    sel.replaceChildren(h('option', { value: '' }, items.length ? 'choose the walk to start from' : 'upload a trial first'),
      ...items.map((m) => h('option', { value: m.id }, sourceLabel(m))));
    if (keep && items.some((m) => m.id === keep)) sel.value = keep;
    renderSourceNote();
  }

  const sourceLabel = (m) => `${m.name || m.kind} · ${m.kind} · ${m.character} · ${m.frames} frames · ${m.id.slice(0, 10)}`;

  /** What Start runs on, in words (the source chosen), and what the job does with it. */
  function renderSourceNote() {
    const m = state.motions.find((x) => x.id === $('source-select').value);
    const capture = !m || m.kind === 'capture';
    character.disabled = fps.disabled = !capture;
    state.startSource = m ? m.id : null;
    $('start-button').textContent = m ? `Start on ${m.name || m.kind}` : 'Start';
    $('source-note').textContent = !m ? 'Choose the walk to start from (an uploaded trial, or a motion).'
      : `Start runs on ${m.name || m.kind} (${m.kind} ${m.id.slice(0, 10)}). `
        + (capture ? 'A raw capture: the job first makes its tutor, one gait cycle of the character at this fps.'
          : `A ${m.kind} with contact forces: it is the tutor itself (character and fps are for captures).`);
  }
  $('source-select').addEventListener('change', renderSourceNote);

  const range = (a) => `${a.exclusive_minimum ? '(' : '['}${a.minimum}, ${a.maximum}${a.exclusive_maximum ? ')' : ']'}`;
  // the axes' fields: built again when the axes arrive later (GET /axes needs the key)
  let gridAxes = [];
  function renderAxes() {
  $('target-fields').replaceChildren(...axes.map((a) => h('label', { class: 'field axis', title: a.doc },
    h('span', { class: 'name' }, a.label),
    h('span', { class: 'with-unit' }, h('input', { type: 'number', step: 'any', id: `target-${a.name}`, name: a.name,
      min: a.minimum, max: a.maximum, placeholder: a.default === null ? "tutor's" : String(a.default) }),
    h('span', { class: 'unit' }, a.unit)),
    h('small', { class: 'hint' }, `${a.name} ${range(a)}`))));
  if (!axes.length) $('target-fields').append(h('p', { class: 'hint' }, 'the targets come with your API key (GET /axes)'));
  gridAxes = axes.filter((a) => a.grid);
  $('grid-fields').replaceChildren(...gridAxes.map((a) => h('label', { class: 'field axis wide', title: a.doc },
    h('span', { class: 'name' }, `${a.label} values`),
    h('span', { class: 'with-unit' }, h('input', { type: 'text', id: `grid-${a.name}`, name: a.name,
      placeholder: 'values, comma separated', spellcheck: 'false' }), h('span', { class: 'unit' }, a.unit)),
    h('small', { class: 'hint' }, `${a.name} ${range(a)}`))));
  }
  renderAxes();
  $('grid-fields').addEventListener('input', () => {
    const grid = readGrid();
    $('grid-cells').textContent = grid.error || `${grid.cells} cell${grid.cells === 1 ? '' : 's'} (at most ${MAX_GRID_CELLS})`;
  });

  const controlProps = (schema && schema.control && schema.control.properties) || {};
  $('control-fields').replaceChildren(...Object.entries(controlProps).map(([name, p]) => {
    const control = p.enum
      ? h('select', { id: `control-${name}` }, ...p.enum.map((v) => h('option', { value: v, selected: v === p.default }, v)))
      : h('input', { type: 'number', id: `control-${name}`, step: p.type === 'integer' ? 1 : 'any',
        min: p.minimum ?? p.exclusiveMinimum, max: p.maximum, placeholder: String(p.default) });
    return h('label', { class: 'field', title: p.description || name },
      h('span', { class: 'name' }, name.replaceAll('_', ' ')), control,
      h('small', { class: 'hint' }, p.description || (p.default !== undefined ? `default ${p.default}` : '')));
  }));

  const mode = () => document.querySelector('input[name="start-mode"]:checked').value;
  for (const r of document.querySelectorAll('input[name="start-mode"]')) {
    r.addEventListener('change', () => {
      const lib = mode() === 'library';
      $('target-fields').hidden = lib;
      $('grid-fields').hidden = $('grid-cells').hidden = !lib;
    });
  }

  /** A number from an input, or undefined when empty; throws on a value that is not one. */
  function numberOf(el, what) {
    if (el.validity && el.validity.badInput) throw new Error(`${what}: not a number`);
    const v = el.value.trim();
    if (!v) return undefined;
    const x = Number(v);
    if (!Number.isFinite(x)) throw new Error(`${what}: not a number`);
    return x;
  }

  function readGrid() {
    const grid = {};
    let cells = 1;
    for (const a of gridAxes) {
      const text = $(`grid-${a.name}`).value.trim();
      if (!text) continue;
      const values = text.split(/[\s,;]+/).filter(Boolean).map(Number);
      if (values.some((x) => !Number.isFinite(x))) return { error: `${a.label}: give numbers separated by commas` };
      grid[a.name] = values;
      cells *= values.length;
    }
    if (!Object.keys(grid).length) return { error: 'give the values of at least one axis' };
    return { grid, cells };
  }

  function requestBody() {
    const tutor = character.value ? { character: character.value } : {};
    const f = numberOf(fps, 'fps');
    if (f !== undefined) tutor.fps = f;
    const control = {};
    for (const [name, p] of Object.entries(controlProps)) {
      const el = $(`control-${name}`);
      if (p.enum) control[name] = el.value;
      else {
        const x = numberOf(el, name.replaceAll('_', ' '));
        if (x !== undefined) control[name] = x;
      }
    }
    if (mode() === 'library') {
      const { grid, error } = readGrid();
      if (error) throw new Error(error);
      return { grid, control, tutor };
    }
    const target = {};
    for (const a of axes) {
      const x = numberOf($(`target-${a.name}`), a.label);
      if (x !== undefined) target[a.name] = x;
    }
    if (!Object.keys(target).length) throw new Error('set at least one target value');
    return { target, control, tutor };
  }

  async function start(e) {
    e.preventDefault();
    const out = $('start-status');
    const source = $('source-select').value;
    const kind = mode();
    let body;
    try {
      if (!source) throw new Error('choose the walk to start from (upload a trial first, or pick a motion)');
      body = requestBody();
    } catch (err) {
      state.startStatus = 'error';
      status(out, 'error', err.message);
      return;
    }
    const button = $('start-button');
    button.disabled = true;
    state.startStatus = 'busy';
    status(out, 'busy', 'starting…');
    try {
      const path = kind === 'library' ? `/motions/${source}/library` : `/motions/${source}/extrapolate`;
      const made = await api(path, { method: 'POST', json: body });
      state.startedId = made.id;
      state.startStatus = 'ok';
      const from = state.motions.find((x) => x.id === source);
      status(out, 'ok', `started ${kind === 'library' ? 'library' : 'job'} ${made.id} on ${from ? from.name || from.kind : source}: `
        + 'follow it below');
      ctx.refreshLists();
      ctx.started(kind, made.id); // follows it until it ends: not awaited, the form stays usable
      $(kind === 'library' ? 'library-panel' : 'job-panel').scrollIntoView({ block: 'nearest' });
    } catch (err) {
      state.startStatus = 'error';
      status(out, 'error', err.message);
      if (!(err instanceof ApiError)) noteError('start', err);
    } finally {
      button.disabled = false;
    }
  }

  $('upload-form').addEventListener('submit', upload);
  $('start-form').addEventListener('submit', start);
  renderFiles();

  /** Another key: nothing of the previous one stays in the form. */
  function reset() {
    Object.assign(state, { uploadStatus: null, uploadedId: null, startStatus: null, startedId: null });
    clearTrial();
    for (const id of ['upload-status', 'start-status']) status($(id), '', '');
    $('upload-facts').hidden = true;
    sourcesShown = '';
    renderSources();
  }

  return { renderSources, reset, renderAxes };
}

/** A JSON Schema property without its null branch (an optional field is anyOf [schema, null]). */
function plain(prop) {
  if (!prop || !Array.isArray(prop.anyOf)) return prop;
  const branch = prop.anyOf.find((p) => p.type !== 'null') || {};
  return { ...branch, ...prop, anyOf: undefined, nullable: prop.anyOf.some((p) => p.type === 'null') };
}

function sizeText(bytes) {
  return bytes < 1024 ? `${bytes} B` : bytes < 1024 ** 2 ? `${(bytes / 1024).toFixed(1)} kB` : `${(bytes / 1024 ** 2).toFixed(1)} MB`;
}

const fmtNum = (x) => (typeof x === 'number' && Number.isFinite(x) ? String(+x.toPrecision(4)) : '–');
