// The kac viewer: a client of the public /v1 API only (the reference client for front ends). Upload or pick a
// shape, run any analysis from a form built from the OpenAPI document, follow its progress by server-sent events,
// and look at every per-vertex array of the result on the shape (arrays fetched as .npy). The view lives in the
// URL's fragment (#shape=…&job=…&array=…&column=…&vertex=…), so every view can be linked to.
import { Viewer } from './render.js';
import { plotCurves, plotMatrix, plotStaircase } from './plot.js';

const $ = (id) => document.getElementById(id);
const state = { shape: null, summary: null, geometry: null, job: null, result: null, arrays: {}, array: null, column: 0, vertex: null, jobSource: null };
const viewer = new Viewer($('canvas'));
// The second shape of a correspondence, beside the first.
const viewer2 = new Viewer($('canvas2'));
// For tests and the curious: the viewer's state and renderer.
window.kac = { state, viewer, viewer2, errors: [], pair: null };
window.addEventListener('error', (e) => window.kac.errors.push(String(e.message)));
const consoleError = console.error.bind(console);
console.error = (...args) => {
  window.kac.errors.push(args.map(String).join(' '));
  consoleError(...args);
};
window.addEventListener('unhandledrejection', (e) => window.kac.errors.push(String(e.reason)));

// ---- the API -------------------------------------------------------------------------------------------------

$('key').value = localStorage.getItem('kac-key') || '';
$('key').addEventListener('change', () => {
  localStorage.setItem('kac-key', $('key').value.trim());
  loadShapes();
});

function auth(h = {}) {
  const k = localStorage.getItem('kac-key');
  return k ? { ...h, Authorization: `Bearer ${k}` } : h;
}

class Problem extends Error {
  constructor(p) {
    super(`${p.title || 'Error'} (${p.code || p.status}): ${p.detail || ''}`);
    this.problem = p;
  }
}

async function api(method, path, body, contentType = 'application/json') {
  const init = { method, headers: auth(body === undefined ? {} : { 'Content-Type': contentType }) };
  if (body !== undefined) init.body = contentType === 'application/json' ? JSON.stringify(body) : body;
  const r = await fetch(path, init);
  const type = r.headers.get('content-type') || '';
  if (!r.ok) {
    const p = type.includes('json') ? await r.json() : { status: r.status, title: r.statusText, detail: await r.text() };
    throw new Problem(p);
  }
  return type.includes('json') ? r.json() : r.arrayBuffer();
}

function showError(e) {
  const box = $('error');
  if (!e) {
    box.hidden = true;
    return;
  }
  box.hidden = false;
  box.textContent = e.problem ? `${e.problem.title} — ${e.problem.code}\n${e.problem.detail}` : String(e.message || e);
}

async function guarded(f) {
  try {
    showError(null);
    return await f();
  } catch (e) {
    showError(e);
    return undefined;
  }
}

// A .npy of float64 (C order, 1-D or 2-D): { rows, cols, data }.
function parseNpy(buf) {
  const bytes = new Uint8Array(buf);
  const major = bytes[6];
  const hlen = major === 1 ? bytes[8] | (bytes[9] << 8) : new DataView(buf).getUint32(8, true);
  const start = major === 1 ? 10 : 12;
  const header = new TextDecoder().decode(bytes.subarray(start, start + hlen));
  const shape = header.match(/'shape':\s*\(([^)]*)\)/)[1].split(',').map((s) => s.trim()).filter(Boolean).map(Number);
  return { rows: shape[0], cols: shape[1] || 1, data: new Float64Array(buf.slice(start + hlen)) };
}

// The geometry of a stored shape: positions, triangles (a tet mesh's boundary), segments, and the map from the
// upload's vertex numbering (the rows of every array) to the geometry's vertices.
function parseGeometry(buf) {
  const dv = new DataView(buf);
  const hlen = dv.getUint32(0, true);
  const head = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, hlen)));
  let at = 4 + hlen;
  at += (4 - (at % 4)) % 4;
  const take = (Type, n) => {
    const a = new Type(buf, at, n);
    at += n * 4;
    return a;
  };
  return {
    head,
    positions: take(Float32Array, 3 * head.vertices),
    triangles: take(Uint32Array, 3 * head.triangles),
    segments: take(Uint32Array, 2 * head.segments),
    inputToVertex: take(Uint32Array, head.input_rows),
  };
}

// ---- the URL fragment ------------------------------------------------------------------------------------------

function writeLink() {
  const p = new URLSearchParams();
  if (state.shape) p.set('shape', state.shape);
  if (state.job) p.set('job', state.job);
  if (state.array) p.set('array', state.array);
  if (state.array) p.set('column', String(state.column));
  if (state.vertex !== null) p.set('vertex', String(state.vertex));
  const hash = `#${p}`;
  if (location.hash !== hash) history.replaceState(null, '', hash);
  $('link').href = location.href;
}

async function restore() {
  const p = new URLSearchParams(location.hash.slice(1));
  if (p.get('shape')) await selectShape(p.get('shape'));
  if (p.get('vertex')) pickVertex(Number(p.get('vertex')), false);
  if (p.get('job')) await openJob(p.get('job'), p.get('array'), Number(p.get('column') || 0));
}

// ---- shapes ----------------------------------------------------------------------------------------------------

// The stored shapes by id, as the list gave them; and the file names of the shapes uploaded from this page (the
// service keeps no file name).
const shapeIndex = new Map();
const fileNames = new Map();

async function loadShapes() {
  const list = await guarded(() => api('GET', '/v1/shapes?limit=1000'));
  if (!list) return;
  const sel = $('shapes');
  const target = $('target');
  const keep = target.value;
  sel.length = 1;
  target.length = 1;
  shapeIndex.clear();
  for (const s of list.items) {
    shapeIndex.set(s.id, s);
    const label = `${s.id.slice(0, 12)} — ${s.summary.kind} ${s.summary.vertices ?? ''} v`;
    sel.add(new Option(label, s.id));
    target.add(new Option(label, s.id));
  }
  if (state.shape) sel.value = state.shape;
  target.value = keep;
  $('match').disabled = !state.shape || !target.value;
}

// Uploads as multipart with the file's name, so the server reads the format from the name as it would from any
// client (every extension kac knows, e.g. .msh, .mesh, .pts), or from the content.
async function upload(file) {
  await guarded(async () => {
    const form = new FormData();
    form.append('file', file, file.name);
    const r = await fetch('/v1/shapes', { method: 'POST', headers: auth(), body: form });
    const s = await r.json();
    if (!r.ok) throw new Problem(s);
    fileNames.set(s.id, file.name);
    await loadShapes();
    await selectShape(s.id);
  });
}

// The truth table for the selected shape (GET /v1/analyses?shape_id=): analyses that do not apply to its class
// are disabled in the form, with the reason as their tooltip; the first that applies is selected.
async function markApplicable(id) {
  let table;
  try {
    table = await api('GET', `/v1/analyses?shape_id=${encodeURIComponent(id)}`);
  } catch (e) {
    // Without the table every analysis stays offered; the service refuses what does not apply (unsupported).
    for (const o of $('analysis').options) o.disabled = false;
    return;
  }
  const rows = Object.fromEntries(table.analyses.map((a) => [a.name, a]));
  for (const o of $('analysis').options) {
    const row = rows[o.value];
    o.disabled = row ? !row.applies : false;
    o.title = row && !row.applies ? row.reason : row ? row.summary : '';
  }
  const sel = $('analysis');
  if (sel.selectedOptions[0]?.disabled) {
    const first = [...sel.options].find((o) => !o.disabled);
    if (first) {
      sel.value = first.value;
      renderForm(first.value);
    }
  }
  $('report').dataset.class = table.class || '';
}

async function selectShape(id) {
  await guarded(async () => {
    const s = await api('GET', `/v1/shapes/${encodeURIComponent(id)}`);
    state.shape = id;
    state.summary = s.summary;
    state.job = null;
    state.result = null;
    $('warnings').hidden = true;
    state.array = null;
    state.vertex = null;
    $('shapes').value = id;
    const r = s.summary;
    const facts = [
      `${r.kind}, ${r.vertices ?? '?'} vertices`,
      r.faces !== undefined ? `${r.faces} faces` : '',
      r.components !== undefined ? `${r.components} component(s)` : '',
      r.genus !== undefined && r.genus !== null ? `genus ${r.genus}` : '',
      r.boundary_loops !== undefined ? `${r.boundary_loops} boundary loop(s)` : '',
      r.area ? `area ${r.area.toPrecision(5)}` : '',
      (r.report?.repairs || []).length ? `repairs: ${r.report.repairs.map((x) => `${x.code} ×${x.count}`).join(', ')}` : 'no repairs',
    ].filter(Boolean);
    $('report').replaceChildren(...facts.map((f) => Object.assign(document.createElement('div'), { textContent: f })));
    await markApplicable(id);
    const g = parseGeometry(await api('GET', `/v1/shapes/${encodeURIComponent(id)}/geometry`));
    state.geometry = g;
    viewer.setGeometry(g);
    $('run').disabled = false;
    $('search-run').disabled = false;
    markNeighbour();
    $('match').disabled = !$('target').value;
    leavePair();
    $('controls').hidden = true;
    $('colourbar').hidden = true;
    $('picked-box').hidden = true;
    window.kac.firstFrame = performance.now();
    writeLink();
  });
}

$('shapes').addEventListener('change', () => $('shapes').value && selectShape($('shapes').value));
$('file').addEventListener('change', () => $('file').files[0] && upload($('file').files[0]));
const drop = $('upload');
drop.addEventListener('dragover', (e) => {
  e.preventDefault();
  drop.classList.add('over');
});
drop.addEventListener('dragleave', () => drop.classList.remove('over'));
drop.addEventListener('drop', (e) => {
  e.preventDefault();
  drop.classList.remove('over');
  if (e.dataTransfer.files[0]) upload(e.dataTransfer.files[0]);
});

// ---- analyses, from the OpenAPI document ------------------------------------------------------------------------

let doc = null;
const variants = {};

// A property's schema with references followed and `oneOf: [X]` / `oneOf: [null, X]` (optional) unwrapped; the
// outer default and description kept.
function resolve(schema) {
  if (!schema) return {};
  if (schema.$ref) return { ...resolve(doc.components.schemas[schema.$ref.split('/').pop()]), ...without(schema, '$ref') };
  const alts = (schema.oneOf || schema.allOf || []).filter((s) => s.type !== 'null');
  if (alts.length === 1) return { ...resolve(alts[0]), ...without(schema, 'oneOf', 'allOf') };
  return schema;
}

function without(o, ...keys) {
  const c = { ...o };
  for (const k of keys) delete c[k];
  return c;
}

function typeOf(s) {
  const t = Array.isArray(s.type) ? s.type.find((x) => x !== 'null') : s.type;
  if (s.enum) return 'enum';
  return t || (s.properties ? 'object' : 'string');
}

// One input per scalar property; objects one level deep as fieldsets; arrays as comma-separated numbers.
function field(name, schema, path) {
  const s = resolve(schema);
  const t = typeOf(s);
  const label = document.createElement('label');
  label.title = s.description || '';
  label.append(`${name} `);
  let input;
  if (t === 'boolean') {
    input = document.createElement('input');
    input.type = 'checkbox';
    input.checked = s.default === true;
  } else if (t === 'enum') {
    input = document.createElement('select');
    input.add(new Option(s.default !== undefined && s.default !== null ? `(default: ${s.default})` : '(default)', ''));
    for (const v of s.enum.filter((v) => v !== null)) input.add(new Option(v, v));
  } else {
    input = document.createElement('input');
    input.type = 'text';
    input.placeholder = s.default !== undefined && s.default !== null ? String(s.default) : t === 'array' ? 'a, b, …' : 'default';
  }
  input.dataset.path = path;
  input.dataset.kind = t;
  input.dataset.initial = input.type === 'checkbox' ? String(input.checked) : '';
  label.append(input);
  return label;
}

function renderForm(name) {
  const form = $('params');
  form.innerHTML = '';
  const v = variants[name];
  for (const [prop, schema] of Object.entries(v.properties || {})) {
    if (prop === 'analysis') continue;
    const s = resolve(schema);
    if (typeOf(s) === 'object' && s.properties) {
      const fs = document.createElement('fieldset');
      const lg = document.createElement('legend');
      lg.textContent = prop;
      fs.append(lg);
      for (const [p, ps] of Object.entries(s.properties)) fs.append(field(p, ps, `${prop}.${p}`));
      form.append(fs);
    } else {
      form.append(field(prop, schema, prop));
    }
  }
  // Sensible first values for looking at something: eigenvectors of a spectrum.
  const ev = form.querySelector('[data-path="eigenvectors"]');
  if (ev) ev.checked = true;
}

// The request from the form: only what was set (the server fills in the rest and echoes it).
function request() {
  const req = { shape_id: state.shape, analysis: $('analysis').value };
  for (const input of $('params').querySelectorAll('[data-path]')) {
    const kind = input.dataset.kind;
    let value;
    if (kind === 'boolean') {
      if (String(input.checked) === input.dataset.initial && input.dataset.path !== 'eigenvectors') continue;
      value = input.checked;
    } else if (input.value.trim() === '') continue;
    else if (kind === 'integer') value = parseInt(input.value, 10);
    else if (kind === 'number') value = parseFloat(input.value);
    else if (kind === 'array') value = input.value.split(',').map((x) => x.trim()).filter(Boolean).map(Number);
    else value = input.value;
    const path = input.dataset.path.split('.');
    let o = req;
    for (const p of path.slice(0, -1)) o = o[p] = o[p] || {};
    o[path[path.length - 1]] = value;
  }
  return req;
}

async function loadAnalyses() {
  doc = await api('GET', '/openapi.json');
  for (const variant of resolve(doc.components.schemas.Analysis).oneOf) {
    // A variant with flattened parts (allOf) has its properties spread over them.
    const v = { properties: {} };
    for (const part of variant.allOf || [variant]) Object.assign(v.properties, resolve(part).properties || {});
    const name = v.properties.analysis.enum[0];
    variants[name] = v;
    $('analysis').add(new Option(name, name));
  }
  const fmt = resolve(doc.components.schemas.Format || {});
  window.kac.formats = fmt.enum || [];
  $('formats').textContent = (fmt.enum || []).join(', ');
  $('analysis').addEventListener('change', () => renderForm($('analysis').value));
  renderForm($('analysis').value);
  searchDescriptors();
}

// ---- jobs --------------------------------------------------------------------------------------------------------

let events = null;
// Each follow has a number; an older one (a poll loop still running) stops when a newer starts.
let following = 0;

async function submit(req) {
  await guarded(async () => {
    const job = await api('POST', '/v1/jobs', req);
    await follow(job);
  });
}

// Follows a job by its server-sent events until it ends; then opens its result.
function follow(job) {
  const mine = ++following;
  return new Promise((resolve) => {
    state.job = job.id;
    writeLink();
    $('progress').hidden = false;
    $('cancel').hidden = false;
    if (events) events.close();
    // EventSource cannot send an Authorization header: with a key, poll instead.
    const done = async (v) => {
      $('progress').hidden = true;
      $('cancel').hidden = true;
      $('phase').textContent = v.status;
      if (v.status === 'succeeded') await openJob(v.id);
      else if (v.error) showError(new Problem(v.error));
      resolve();
    };
    const update = (v) => {
      if (mine !== following) {
        resolve();
        return true;
      }
      $('phase').textContent = `${v.status} · ${v.progress.phase}${v.progress.wanted ? ` ${v.progress.converged}/${v.progress.wanted}` : ''}`;
      if (v.progress.wanted) {
        $('progress').max = v.progress.wanted;
        $('progress').value = v.progress.converged;
      } else $('progress').removeAttribute('value');
      if (['succeeded', 'failed', 'canceled'].includes(v.status)) {
        // A finished job's warnings are its result's; until it is shown, none (not the previous result's).
        $('warnings').hidden = true;
        if (events) events.close();
        events = null;
        done(v);
        return true;
      }
      return false;
    };
    if (!localStorage.getItem('kac-key')) {
      events = new EventSource(`/v1/jobs/${encodeURIComponent(job.id)}/events`);
      events.addEventListener('job', (e) => update(JSON.parse(e.data)));
      events.onerror = () => {};
    } else {
      const poll = async () => {
        try {
          const v = await api('GET', `/v1/jobs/${encodeURIComponent(job.id)}`);
          if (!update(v)) setTimeout(poll, 300);
        } catch (e) {
          $('progress').hidden = true;
          $('cancel').hidden = true;
          showError(e);
          resolve();
        }
      };
      poll();
    }
  });
}

$('run').addEventListener('click', () => submit(request()));
// Shape-DNA of every stored shape (scale-invariant: retrieval's default options) and the distances between them, as a
// job. By shape-DNA rather than fused: a fused distance needs spreads over three shapes or more, and a viewer often
// holds two.
$('compare').addEventListener('click', () =>
  guarded(async () => {
    const r = await api('POST', '/v1/compare?wait=0', { descriptor: 'shape-dna' });
    await follow(r.status && r.links ? r : { id: r.result_id, status: 'succeeded' });
  }),
);
$('cancel').addEventListener('click', () => state.job && guarded(() => api('POST', `/v1/jobs/${encodeURIComponent(state.job)}/cancel`)));

async function openJob(id, array, column = 0) {
  await guarded(async () => {
    const job = await api('GET', `/v1/jobs/${encodeURIComponent(id)}`);
    if (job.status !== 'succeeded') return follow(job);
    if (job.shape_id && job.shape_id !== state.shape) await selectShape(job.shape_id);
    state.analysis = job.analysis;
    if (variants[job.analysis] && $('analysis').value !== job.analysis) {
      $('analysis').value = job.analysis;
      renderForm(job.analysis);
    }
    state.job = id;
    const r = await api('GET', `/v1/results/${encodeURIComponent(id)}?values=false`);
    state.result = r;
    state.arrays = {};
    $('summary').textContent = JSON.stringify(r, (k, v) => (Array.isArray(v) && v.length > 40 ? `[${v.length} values]` : v), 1);
    // Warnings (numbers outside their domain of validity) above the numbers, where they are seen first.
    const warnings = (r.warnings || []).map((w) => `⚠ ${w.code}: ${w.message}`);
    $('warnings').textContent = warnings.join('\n');
    $('warnings').hidden = warnings.length === 0;
    if (r.analysis === 'correspondence') {
      await showPair(r, id);
      writeLink();
      return;
    }
    leavePair();
    // Per-vertex arrays only (they have a coloured PLY); an operator's matrices are links in the summary.
    const names = Object.keys(r.arrays || {}).filter((n) => r.arrays[n].ply);
    $('array').innerHTML = '';
    for (const n of names) $('array').add(new Option(n, n));
    $('controls').hidden = names.length === 0;
    plots(r);
    if (names.length) await showArray(array && names.includes(array) ? array : names[0], column);
    writeLink();
  });
}

// Fetches an array (.npy) once, and shows one column of it.
async function showArray(name, column) {
  if (!state.arrays[name]) state.arrays[name] = parseNpy(await api('GET', `/v1/results/${encodeURIComponent(state.job)}/arrays/${encodeURIComponent(name)}.npy`));
  const a = state.arrays[name];
  state.array = name;
  state.column = Math.max(0, Math.min(column, a.cols - 1));
  $('array').value = name;
  const slider = $('column');
  slider.max = String(a.cols - 1);
  slider.value = String(state.column);
  colour();
}

// Colours the shape by the current column: each vertex takes the value of an upload row that maps to it.
function colour() {
  const a = state.arrays[state.array], g = state.geometry;
  if (!a || !g) return;
  const n = g.positions.length / 3;
  const values = new Float32Array(n).fill(NaN);
  const map = g.inputToVertex;
  for (let row = 0; row < a.rows && row < map.length; row++) {
    const v = map[row];
    if (v < n) values[v] = a.data[row * a.cols + state.column];
  }
  let lo = Infinity, hi = -Infinity;
  for (const x of values) {
    if (isFinite(x)) {
      lo = Math.min(lo, x);
      hi = Math.max(hi, x);
    }
  }
  if (!isFinite(lo)) [lo, hi] = [0, 1];
  viewer.isolines = $('isolines').checked || state.array === 'distance' ? 12 : 0;
  viewer.setValues(values, lo, hi);
  $('colourbar').hidden = false;
  $('cb-lo').textContent = lo.toPrecision(4);
  $('cb-hi').textContent = hi.toPrecision(4);
  const meta = state.result.arrays[state.array] || {};
  const col = meta.columns ? meta.columns[state.column] : null;
  const what = {
    eigenvectors: 'λ', hks: 't', wks: 'e', si_hks: 'ω', heat_kernel: 't', heat: 't', gps: 'λ', embedding: 'λ',
    wave: 't', schrodinger_re: 't', schrodinger_im: 't', diffused: 't',
  }[state.array];
  $('column-label').textContent = what ? `${what} (column)` : 'column';
  $('column-value').textContent = `${state.column}${col !== null && col !== undefined ? ` — ${what || 'value'} = ${Number(col).toPrecision(5)}` : ''}`;
  if (state.vertex !== null) vertexPlot();
  writeLink();
}

$('array').addEventListener('change', () => guarded(() => showArray($('array').value, 0)));
$('column').addEventListener('input', () => {
  state.column = Number($('column').value);
  colour();
});
$('isolines').addEventListener('change', colour);

// ---- picking -----------------------------------------------------------------------------------------------------

// The upload's row of a geometry vertex (sources are given in the upload's numbering).
function rowOf(v) {
  const map = state.geometry.inputToVertex;
  for (let row = 0; row < map.length; row++) if (map[row] === v) return row;
  return v;
}

function pickVertex(v, link = true) {
  state.vertex = v;
  viewer.setMarker(v);
  if (window.kac.pair) markMatch('source', v);
  $('picked-box').hidden = false;
  $('picked').textContent = `${rowOf(v)}`;
  vertexPlot();
  if (link) writeLink();
}

viewer.onpick = (v) => pickVertex(v);
$('geodesic').addEventListener('click', () => submit({ shape_id: state.shape, analysis: 'geodesic', sources: [rowOf(state.vertex)] }));
$('heat').addEventListener('click', () => submit({ shape_id: state.shape, analysis: 'heat', sources: [rowOf(state.vertex)] }));
// Evolutions from a bump at the picked vertex, over times scaled to the shape (its area: a wave crosses a
// unit-area surface in about one time unit); the slider then plays them.
const evolutionTimes = () => {
  const scale = Math.sqrt(state.summary?.area || 1);
  return Array.from({ length: 24 }, (_, i) => (i * scale) / 12);
};
$('wave').addEventListener('click', () =>
  submit({ shape_id: state.shape, analysis: 'wave', k: 200, times: evolutionTimes(), source: rowOf(state.vertex) }),
);
$('schrodinger').addEventListener('click', () =>
  submit({ shape_id: state.shape, analysis: 'schrodinger', k: 200, times: evolutionTimes().map((t) => t / 10), source: rowOf(state.vertex) }),
);

// ---- correspondence: two shapes side by side ------------------------------------------------------------------

// The x coordinate of each upload row of a shape (NaN for a row validation dropped): the function that travels.
function xOfRows(g) {
  const n = g.positions.length / 3;
  return Array.from(g.inputToVertex, (v) => (v < n ? g.positions[3 * v] : NaN));
}

$('target').addEventListener('change', () => ($('match').disabled = !state.shape || !$('target').value));
$('match').addEventListener('click', () =>
  guarded(async () => {
    const values = xOfRows(state.geometry).map((x) => (Number.isFinite(x) ? x : 0));
    const body = { source_id: state.shape, target_id: $('target').value, transfer: { values } };
    const r = await api('POST', '/v1/correspondence?wait=0', body);
    await follow(r.status && r.links ? r : { id: r.result_id, status: 'succeeded' });
  }),
);

function leavePair() {
  window.kac.pair = null;
  $('canvas2').hidden = true;
  $('pair-info').textContent = '';
  viewer.setMarker(null);
}

// A correspondence's result: the target beside the source, the source coloured by its x coordinate and the target
// by that function carried over by the functional map (`transferred`); a vertex picked on either marks its match
// on the other.
async function showPair(r, job) {
  const get = async (name) => parseNpy(await api('GET', `/v1/results/${encodeURIComponent(job)}/arrays/${name}.npy`));
  const g2 = parseGeometry(await api('GET', `/v1/shapes/${encodeURIComponent(r.target_id)}/geometry`));
  const pair = { target: r.target_id, geometry: g2, s2t: await get('source_to_target'), t2s: await get('target_to_source') };
  pair.transferred = r.arrays.transferred ? await get('transferred') : null;
  // Another shape or result opened while these arrived: this pair is no longer the view.
  if (state.job !== job || state.shape !== r.source_id) return;
  $('canvas2').hidden = false;
  viewer2.setGeometry(g2);
  window.kac.pair = pair;
  const rows = (g, data) => {
    const n = g.positions.length / 3;
    const out = new Float32Array(n).fill(NaN);
    g.inputToVertex.forEach((v, row) => {
      if (v < n) out[v] = data[row];
    });
    return out;
  };
  const source = rows(state.geometry, xOfRows(state.geometry));
  // Without `transferred` (a result asked without it), each target vertex takes its match's x.
  const xs = xOfRows(state.geometry);
  const carried = pair.transferred ? pair.transferred.data : Array.from(pair.t2s.data, (row) => (Number.isFinite(row) ? xs[row] : NaN));
  const target = rows(g2, carried);
  let lo = Infinity, hi = -Infinity;
  for (const x of source) if (Number.isFinite(x)) [lo, hi] = [Math.min(lo, x), Math.max(hi, x)];
  if (!Number.isFinite(lo)) [lo, hi] = [0, 1];
  viewer.isolines = 12;
  viewer2.isolines = 12;
  viewer.setValues(source, lo, hi);
  viewer2.setValues(target, lo, hi);
  $('colourbar').hidden = false;
  $('cb-lo').textContent = lo.toPrecision(4);
  $('cb-hi').textContent = hi.toPrecision(4);
  $('controls').hidden = true;
  $('pair-info').textContent = `left: this shape, coloured by x; right: ${r.target_id.slice(0, 12)}, by x carried over (${pair.transferred ? 'functional map' : 'vertex map'}); orthogonality defect ${Number(r.orthogonality_defect).toPrecision(3)}. Pick a vertex on either side.`;
  if (state.vertex !== null) markMatch('source', state.vertex);
}

// Marks the match of a vertex picked on one side on the other; `window.kac.pair` holds both (geometry indices).
function markMatch(side, v) {
  const pair = window.kac.pair;
  const [from, to, map] = side === 'source' ? [state.geometry, pair.geometry, pair.s2t] : [pair.geometry, state.geometry, pair.t2s];
  let row = -1;
  for (let i = 0; i < from.inputToVertex.length; i++) if (from.inputToVertex[i] === v) { row = i; break; }
  const other = row >= 0 ? map.data[row] : NaN;
  const w = Number.isFinite(other) ? to.inputToVertex[other] : null;
  if (side === 'source') {
    pair.sourceVertex = v;
    pair.targetVertex = w;
    viewer2.setMarker(w);
  } else {
    pair.targetVertex = v;
    pair.sourceVertex = w;
    viewer2.setMarker(v);
    // The match becomes the picked vertex of the shape (its panel and plot follow), or nothing is picked.
    state.vertex = w;
    viewer.setMarker(w);
    $('picked-box').hidden = w === null;
    if (w !== null) {
      $('picked').textContent = `${rowOf(w)}`;
      vertexPlot();
      writeLink();
    }
  }
  pair.rows = { source: side === 'source' ? row : other, target: side === 'source' ? other : row };
}

viewer2.onpick = (v) => window.kac.pair && markMatch('target', v);

// ---- search: the stored shapes nearest to this one ----------------------------------------------------------------

// POST /v1/search from the shape shown, by one fingerprint family or their fusion. A 202 means the shape's
// fingerprint job is still running: the job is polled until it ends, then the search is asked again. The answer is
// a table of neighbours (each row shows its shape when chosen), with the distance per family of a fused search.

// Each search has a number; an older one (still waiting or polling) stops when a newer starts.
let searching = 0;

// The descriptors the OpenAPI document lists (an enum, or one single-value enum per variant), in place of the
// page's own list; the page's list stays when the document has none.
function searchDescriptors() {
  const schema = doc?.components?.schemas?.Descriptor;
  if (!schema) return;
  const s = resolve(schema);
  const choices = s.enum
    ? s.enum.filter((v) => typeof v === 'string').map((v) => ({ value: v, title: '' }))
    : (s.oneOf || []).flatMap((a) => (a.enum || []).filter((v) => typeof v === 'string').map((v) => ({ value: v, title: a.description || '' })));
  if (!choices.length) return;
  const sel = $('search-descriptor');
  const keep = sel.value || 'fused';
  sel.length = 0;
  for (const c of choices) {
    const o = new Option(c.value, c.value);
    o.title = c.title;
    sel.add(o);
  }
  sel.value = choices.some((c) => c.value === keep) ? keep : choices[0].value;
}

// A number with 4 significant digits ('—' for none).
const fourDigits = (x) => (typeof x === 'number' && Number.isFinite(x) ? x.toPrecision(4) : '—');

function problemText(e) {
  return e && e.problem ? e.problem.detail || e.problem.title || String(e.message) : String((e && e.message) || e);
}

function searchStatus(text, failed = false) {
  const box = $('search-status');
  box.textContent = text;
  box.classList.toggle('error', failed);
  box.classList.toggle('muted', !failed);
}

// One POST /v1/search: { status, body, location } for a 200 or a 202; a Problem for anything else.
async function postSearch(body) {
  const r = await fetch('/v1/search?wait=30', {
    method: 'POST',
    headers: auth({ 'Content-Type': 'application/json' }),
    body: JSON.stringify(body),
  });
  const type = r.headers.get('content-type') || '';
  const v = type.includes('json') ? await r.json() : { status: r.status, title: r.statusText, detail: await r.text() };
  if (!r.ok) throw new Problem(v);
  return { status: r.status, body: v, location: r.headers.get('Location') };
}

// Polls a job until it ends (or a newer search starts); its last view.
async function fingerprintJob(job, location, mine) {
  const path = location && location.startsWith('/v1/jobs/') ? location : `/v1/jobs/${encodeURIComponent(job.id)}`;
  let v = job;
  while (!['succeeded', 'failed', 'canceled'].includes(v.status)) {
    const p = v.progress || {};
    searchStatus(`fingerprinting… ${p.phase || v.status || ''}${p.wanted ? ` ${p.converged}/${p.wanted}` : ''}`);
    await new Promise((done) => setTimeout(done, 500));
    if (mine !== searching) return v;
    v = await api('GET', path);
  }
  return v;
}

async function runSearch() {
  const mine = ++searching;
  const id = state.shape;
  if (!id) return;
  const count = Number($('search-count').value);
  if (!Number.isInteger(count) || count < 1 || count > 1000) {
    searchStatus('neighbours: a whole number from 1 to 1000', true);
    return;
  }
  const body = { shape_id: id, descriptor: $('search-descriptor').value || 'fused', neighbours: count };
  $('search-panel').setAttribute('aria-busy', 'true');
  try {
    // A 202, its job succeeded, then the search again: twice is the most expected (a job that finished without
    // keeping its fingerprints answers 200 the second time).
    for (let attempt = 0; attempt < 4; attempt++) {
      searchStatus('searching…');
      const r = await postSearch(body);
      if (mine !== searching) return;
      if (r.status !== 202) {
        showNeighbours(r.body, id);
        return;
      }
      const job = await fingerprintJob(r.body, r.location, mine);
      if (mine !== searching) return;
      if (job.status !== 'succeeded') throw new Problem(job.error || { title: `the fingerprint job ${job.status}`, detail: '' });
    }
    throw new Error('the fingerprint job succeeded, but the search still waits for it: search again');
  } catch (e) {
    if (mine === searching) searchStatus(problemText(e), true);
  } finally {
    if (mine === searching) $('search-panel').removeAttribute('aria-busy');
  }
}

function cell(tag, text, data = {}) {
  const c = document.createElement(tag);
  c.textContent = text;
  Object.assign(c.dataset, data);
  return c;
}

// A stored shape's file name, when the page knows it (uploaded from here, or named by the list); and its kind and
// size from the list, for a tooltip.
function shapeName(id) {
  const s = shapeIndex.get(id);
  return fileNames.get(id) || s?.name || s?.file_name || '';
}

function shapeFacts(id) {
  const s = shapeIndex.get(id);
  return s ? `${s.summary.kind}${s.summary.vertices !== undefined ? `, ${s.summary.vertices} vertices` : ''}` : '';
}

// The search's answer as the table: rank, shape, the distance searched by, one column per family of a fused
// search; below it what was searched and the families' weights and spreads.
function showNeighbours(r, query) {
  const neighbours = r.neighbours || [];
  const keys = new Set(neighbours.flatMap((n) => Object.keys(n.distances || {})));
  const order = (r.families || []).map((f) => f.descriptor).filter((d) => keys.has(d));
  const columns = [...order, ...[...keys].filter((k) => !order.includes(k))];
  const table = $('search-table');
  const head = document.createElement('tr');
  head.append(cell('th', '#'), cell('th', 'shape'), cell('th', `distance (${r.descriptor})`), ...columns.map((d) => cell('th', d)));
  for (const th of head.children) th.scope = 'col';
  table.tHead.replaceChildren(head);
  const rows = neighbours.map((n, i) => {
    const tr = document.createElement('tr');
    tr.dataset.shapeId = n.shape_id;
    tr.tabIndex = 0;
    tr.title = [`show ${n.shape_id}`, shapeFacts(n.shape_id)].filter(Boolean).join('\n');
    const who = document.createElement('td');
    who.append(cell('code', String(n.shape_id).slice(0, 12)));
    const name = shapeName(n.shape_id);
    if (name) who.append(Object.assign(cell('div', name), { className: 'name muted' }));
    const distance = cell('td', fourDigits(n.distance), { col: 'distance' });
    distance.dataset.value = String(n.distance);
    tr.append(cell('td', String(i + 1)), who, distance);
    for (const d of columns) {
      const x = n.distances?.[d];
      const c = cell('td', fourDigits(x), { family: d });
      c.dataset.value = String(x);
      tr.append(c);
    }
    const show = () => selectShape(n.shape_id);
    tr.addEventListener('click', show);
    tr.addEventListener('keydown', (e) => {
      if (e.key === 'Enter' || e.key === ' ') {
        e.preventDefault();
        show();
      }
    });
    return tr;
  });
  table.tBodies[0].replaceChildren(...rows);
  table.hidden = false;
  markNeighbour();
  searchStatus(
    neighbours.length
      ? `${neighbours.length} nearest to ${query.slice(0, 12)} by ${r.descriptor}`
      : `no other shape has a ${r.descriptor} fingerprint yet (a bulk upload, or a search from a shape, computes one)`,
  );
  const facts = [`searched ${r.searched} shapes · exact: ${r.exact ? 'yes' : 'no'}${r.incomplete !== undefined && r.incomplete !== null ? ` · incomplete: ${r.incomplete}` : ''}`];
  for (const f of r.families || []) {
    const spread = typeof f.spread === 'number' ? f.spread.toPrecision(3) : '—';
    facts.push(`${f.descriptor}: weight ${Number(f.weight).toPrecision(3)} · spread ${spread}`);
  }
  $('search-facts').replaceChildren(...facts.map((f) => cell('div', f)));
}

// Marks the neighbour that is the shape shown (after its row was chosen).
function markNeighbour() {
  for (const tr of $('search-table').tBodies[0].rows) {
    const current = tr.dataset.shapeId === state.shape;
    tr.classList.toggle('current', current);
    if (current) tr.setAttribute('aria-current', 'true');
    else tr.removeAttribute('aria-current');
  }
}

$('search-run').addEventListener('click', runSearch);

// ---- plots ---------------------------------------------------------------------------------------------------------

function plots(r) {
  $('plot-title').textContent = '';
  $('plot2-title').textContent = '';
  for (const id of ['plot', 'plot2']) $(id).getContext('2d').clearRect(0, 0, $(id).width, $(id).height);
  if (Array.isArray(r.distances) && Array.isArray(r.shape_ids)) {
    // A comparison: the shape-DNA distance matrix, and each shape's nearest neighbours below it.
    $('plot-title').textContent = `Shape-DNA distances (${r.metric || 'euclidean'})`;
    plotMatrix($('plot'), r.distances, r.shape_ids);
    const near = (r.nearest || []).map((n) => `${String(n.shape_id).slice(0, 8)} → ${(n.nearest || []).map((x) => `${String(x.shape_id).slice(0, 8)} (${Number(x.distance).toPrecision(3)})`).join(', ')}`);
    $('plot2-title').textContent = 'Nearest neighbours';
    $('summary').textContent = near.join('\n');
    return;
  }
  const values = r.eigenvalues || r.shape_dna?.eigenvalues;
  if (Array.isArray(values) && values.length) {
    // Weyl's law on a surface: N(λ) ≈ area·λ/(4π); on a solid N(λ) ≈ volume·λ^{3/2}/(6π²) (drawn by its slope at
    // the top).
    const area = state.summary?.area, volume = state.summary?.volume;
    let slope = 0;
    if (state.summary?.kind === 'tet_mesh' && volume) {
      const top = values[values.length - 1];
      slope = (volume * top ** 1.5) / (6 * Math.PI ** 2) / top;
    } else if (area) slope = area / (4 * Math.PI);
    $('plot-title').textContent = 'Spectrum against Weyl\u2019s law';
    plotStaircase($('plot'), values, slope);
  }
}

// The picked vertex's row of the current array against its columns (HKS against t on a log axis).
function vertexPlot() {
  const a = state.arrays[state.array];
  const meta = state.result?.arrays?.[state.array];
  if (!a || !meta || state.vertex === null) return;
  const row = rowOf(state.vertex);
  const ys = Array.from(a.data.subarray(row * a.cols, (row + 1) * a.cols));
  const xs = meta.columns && meta.columns.length === a.cols ? meta.columns : ys.map((_, i) => i);
  const logx = ['hks', 'heat_kernel', 'heat'].includes(state.array);
  $('plot2-title').textContent = `${state.array} at vertex ${row}${logx ? ' against t' : ''}`;
  plotCurves($('plot2'), [{ xs, ys, colour: '#1f4e79' }], { logx, xlabel: logx ? 't' : 'column' });
}

// ---- start -------------------------------------------------------------------------------------------------------

(async () => {
  await guarded(loadAnalyses);
  await loadShapes();
  await restore();
  window.kac.ready = true;
})();
