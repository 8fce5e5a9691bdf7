// The playground's API key prompt, the job form (requests built and validated as the API does)
// and the curl line of a request (see app.js).

import {
  $, el, KEY_STORAGE, U64_MAX, IMAGE_MARK, SVG_MARK, HEX_COLOUR, state, localError, api, parseJson,
  announce, clearError, showError, fmtBytes, jobName,
} from './common.js';
import { openJob } from './view.js';
import { refreshJobs } from '../app.js';

// ---------- API key ----------

export function askForKey() {
  el.keyForm.hidden = false;
  if (!state.keyFocused) { state.keyFocused = true; el.apiKey.focus(); }
}

export function onKeySubmit(e) {
  e.preventDefault();
  const key = el.apiKey.value.trim();
  // Header values must be visible ASCII here; anything else would make fetch() throw.
  if (!/^[\x21-\x7e]+$/.test(key)) {
    showError('The API key may only contain visible ASCII characters.');
    el.apiKey.focus();
    return;
  }
  state.apiKey = key;
  sessionStorage.setItem(KEY_STORAGE, key);
  clearError();
  announce('API key saved for this tab.');
  refreshJobs(true);
  if (state.view) openJob(state.view.id); // restart a stream a 401 stopped
}

// Typing a key applies it at once (no need to press "Use key" before submitting).
export function onKeyInput() {
  const key = el.apiKey.value.trim();
  if (key && !/^[\x21-\x7e]+$/.test(key)) return;
  state.apiKey = key;
  if (key) sessionStorage.setItem(KEY_STORAGE, key);
  else sessionStorage.removeItem(KEY_STORAGE);
}

export function forgetKey() {
  state.apiKey = '';
  sessionStorage.removeItem(KEY_STORAGE);
  el.apiKey.value = '';
  announce('API key forgotten.');
  el.apiKey.focus();
}

// ---------- the form ----------

export function updateMode() {
  const kind = state.file && state.file.kind;
  const cap = el.caption.value.trim() !== '';
  const [mode, label] = kind === 'image'
    ? [cap ? 'Image → SVG, fine-tuned to the caption (when the text models are set up)' : 'Image → SVG (vectorize)', 'Vectorize']
    : kind === 'svg' ? ['Refine your SVG toward the caption', 'Refine it'] : ['Caption → SVG', 'Draw it'];
  el.mode.textContent = mode;
  el.submit.textContent = state.submitting ? 'Submitting…' : label;
  el.method.disabled = kind === 'image'; // the API refuses `method` on vectorize jobs
  el.methodHint.hidden = kind !== 'image';
  // canvas, negative prompt, variations: text jobs only
  el.textFields.hidden = el.aspectHint.hidden = el.variationsHint.hidden = kind === 'image';
  el.captionCount.textContent = String([...el.caption.value].length); // characters, as the API counts
}

export const readDataUrl = (file) => new Promise((resolve, reject) => {
  const r = new FileReader();
  r.onload = () => resolve(String(r.result));
  r.onerror = () => reject(r.error);
  r.readAsDataURL(file);
});

export async function setFile(file) {
  clearFile();
  if (!file) return;
  const name = file.name || 'file';
  const isSvg = file.type === 'image/svg+xml' || /\.svg$/i.test(name);
  const isImage = /^image\/(png|jpeg)$/.test(file.type) || /\.(png|jpe?g)$/i.test(name);
  if (!isSvg && !isImage) {
    el.file.value = '';
    showError(localError('image', `${name} is not a PNG, JPEG or SVG file`));
    return;
  }
  try {
    let data, blob = file;
    if (isSvg) {
      data = await file.text();
      blob = new Blob([data], { type: 'image/svg+xml' });
    } else {
      const url = await readDataUrl(file);
      data = url.slice(url.indexOf(',') + 1); // bare base64
    }
    state.file = { kind: isSvg ? 'svg' : 'image', name, data, previewUrl: URL.createObjectURL(blob) };
    el.filePreview.src = state.file.previewUrl;
    el.fileName.textContent = name;
    el.fileKind.textContent = `${isSvg ? 'SVG to start from' : 'Image to vectorize'} · ${fmtBytes(file.size)}`;
    el.fileChosen.hidden = false;
    clearError();
  } catch (e) {
    showError(`Cannot read ${name}: ${e.message}`);
  }
  updateMode();
}

export function clearFile() {
  if (state.file) URL.revokeObjectURL(state.file.previewUrl);
  state.file = null;
  el.filePreview.removeAttribute('src');
  el.fileChosen.hidden = true;
  updateMode();
}

// An optional integer input; undefined when empty.
export function intField(id, min, max) {
  if ($(id).validity.badInput) throw localError(id, `must be a whole number from ${min} to ${max}`);
  const raw = $(id).value.trim();
  if (raw === '') return undefined;
  const n = Number(raw);
  if (!Number.isInteger(n) || n < min || n > max) throw localError(id, `must be a whole number from ${min} to ${max}`);
  return n;
}

export function readSeed() {
  const raw = el.seed.value.trim();
  if (raw === '') return null;
  if (!/^\d{1,40}$/.test(raw) || BigInt(raw) > U64_MAX) throw localError('seed', `must be a whole number from 0 to ${U64_MAX}`);
  return BigInt(raw).toString(); // without leading zeros, which JSON forbids
}

// JSON text of a body, the seed spliced in as digits (JSON.stringify cannot write a u64).
export const toJson = (body, seed) => {
  const s = JSON.stringify(body);
  return seed == null ? s : `${s.slice(0, -1)},"seed":${seed}}`;
};

// The request the form describes: {json, template, files}. `template` is the same JSON with the
// file's contents replaced by a marker, for the curl command.
export function buildRequest() {
  const f = state.file;
  const kind = f && f.kind === 'image' ? 'vectorize' : 'text';
  const caption = el.caption.value.trim();
  if (!caption && kind === 'text') throw localError('caption', 'is required (or drop an image to vectorize)');
  const body = { kind };
  if (caption) body.caption = caption;
  if (f) body[f.kind] = f.kind === 'svg' ? SVG_MARK : IMAGE_MARK;
  body.style = el.style.value;
  body.preset = el.preset.value;
  if (kind === 'text') body.method = el.method.value;
  for (const [id, min, max] of [['paths', 1, 1024], ['steps', 1, 20000], ['samples', 1, 64]]) {
    const n = intField(id, min, max);
    if (n !== undefined && (id !== 'samples' || kind === 'text')) body[id] = n;
  }
  const priority = intField('priority', -100, 100);
  if (priority) body.priority = priority;
  if (kind === 'text' && !f && !el.retrieval.checked) body.retrieval = false;
  if (kind === 'text' && el.aspect.value) body.aspect = el.aspect.value;
  const negative = el.negativePrompt.value.trim();
  if (kind === 'text' && negative) body.negative_prompt = negative;
  const variations = intField('variations', 1, 6);
  if (kind === 'text' && variations > 1) body.variations = variations;
  Object.assign(body, colourFields());
  const template = toJson(body, readSeed());
  const json = f ? template.split(`"${f.kind === 'svg' ? SVG_MARK : IMAGE_MARK}"`).join(JSON.stringify(f.data)) : template;
  return { json, template, files: f ? { [f.kind]: f.name, svgText: f.kind === 'svg' ? f.data : null } : {} };
}

// The vector stage's options the form sets (validated as the API does): colors, palette,
// background, group, fill; the defaults are left out.
export function colourFields() {
  const out = {};
  const colors = intField('colors', 1, 64);
  if (colors !== undefined) out.colors = colors;
  const palette = el.palette.value.split(/[\s,]+/).filter(Boolean);
  const bad = palette.find((c) => !HEX_COLOUR.test(c));
  if (bad) throw localError('palette', `${bad} is not a colour: write #rgb or #rrggbb`);
  if (palette.length > 64) throw localError('palette', `has ${palette.length} colours; at most 64`);
  if (palette.length) out.palette = palette;
  const bg = el.background.value;
  if (bg === 'transparent') out.background = 'transparent';
  else if (bg === 'color') out.background = el.backgroundColor.value;
  if (el.group.value === 'color') out.group = 'color';
  if (el.fill.value !== 'flat') {
    if (out.colors !== undefined || out.palette) {
      throw localError('fill', 'a gradient fill cannot be combined with colours or a palette');
    }
    out.fill = el.fill.value;
  }
  return out;
}

// The form's colour controls showing `p`'s colors, palette, background, group and fill.
export function setColourFields(p) {
  el.colors.value = p.colors ?? '';
  el.palette.value = (p.palette || []).join(' ');
  const bg = p.background || 'auto';
  el.background.value = bg === 'auto' || bg === 'transparent' ? bg : 'color';
  if (el.background.value === 'color') el.backgroundColor.value = bg;
  el.backgroundColor.hidden = el.background.value !== 'color';
  el.group.value = p.group === 'color' ? 'color' : 'none';
  el.fill.value = p.fill === 'linear' || p.fill === 'radial' ? p.fill : 'flat';
}

export async function onSubmit(e) {
  e.preventDefault();
  if (state.submitting) return;
  clearError();
  await state.fileReading; // a file picked or dropped just now may still be being read
  let req;
  try { req = buildRequest(); } catch (err) { showError(err); return; }
  state.submitting = true;
  el.submit.setAttribute('aria-disabled', 'true'); // not `disabled`, which would drop focus
  updateMode();
  try {
    const res = await api('/jobs', { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: req.json });
    const job = parseJson(await res.text());
    state.requests.set(job.id, { template: req.template, files: req.files });
    announce(`Job submitted: ${jobName(job)}.`);
    openJob(job.id, job);
    refreshJobs();
  } catch (err) {
    if (err.name !== 'AbortError') showError(err);
  } finally {
    state.submitting = false;
    el.submit.removeAttribute('aria-disabled');
    updateMode();
  }
}

// "Use these settings": copies the viewed job's stored params back into the form.
export function reuseParams() {
  const job = state.view && state.view.job;
  const p = job && job.params;
  if (!p) return;
  el.caption.value = p.caption || '';
  el.style.value = p.style;
  el.preset.value = p.preset;
  if (p.method) el.method.value = p.method;
  for (const k of ['paths', 'steps', 'samples', 'seed']) el[k].value = p[k] ?? '';
  el.aspect.value = p.aspect ?? '';
  el.negativePrompt.value = p.negative_prompt ?? '';
  el.variations.value = p.variations > 1 ? p.variations : '';
  setColourFields(p);
  el.priority.value = job.priority || '';
  updateMode();
  announce('Settings copied into the form.');
  el.caption.focus();
}

// ---------- curl ----------

export const shq = (s) => `'${String(s).replace(/'/g, "'\\''")}'`;

// The POST as a shell command. File contents are elided: the command reads them from the file.
export function curlFor(template, files) {
  const notes = [];
  let json = template;
  if (files.svgText != null && files.svgText.length <= 4096) {
    json = json.split(`"${SVG_MARK}"`).join(JSON.stringify(files.svgText)); // small: inline
  }
  let data = shq(json);
  if (files.image) {
    data = data.split(IMAGE_MARK).join(`'"$(base64 -w0 ${shq(files.image)})"'`);
    notes.push(`# The image's base64 is read from ${files.image} (on macOS: base64 -i ${files.image}).`);
  }
  if (json.includes(SVG_MARK)) {
    const svg = files.svg || 'start.svg';
    data = data.split(`"${SVG_MARK}"`).join(`'"$(jq -Rs . ${shq(svg)})"'`);
    notes.push(`# The SVG is read from ${svg} and quoted as a JSON string by jq.`);
  }
  if (files.rebuilt) notes.push('# Rebuilt from the stored params (`retrieval` is not stored; it defaults to true).');
  const lines = [...notes, `curl -sS -X POST ${shq(`${location.origin}/jobs`)} \\`,
    "  -H 'Content-Type: application/json' \\"];
  if (state.apiKey) lines.push(`  -H ${shq(`Authorization: Bearer ${state.apiKey}`)} \\`);
  lines.push(`  --data-binary ${data}`);
  return lines.join('\n');
}

// A job not submitted from this tab: its request, rebuilt from the stored params.
export function templateFromJob(job) {
  const p = job.params || {};
  const body = { kind: job.kind };
  if (p.caption != null) body.caption = p.caption;
  if (p.has_image) body.image = IMAGE_MARK;
  if (p.has_svg) body.svg = SVG_MARK;
  for (const k of ['style', 'preset', 'method', 'paths', 'steps', 'aspect', 'width', 'height', 'negative_prompt',
    'colors', 'palette', 'background', 'group', 'fill']) if (p[k] != null) body[k] = p[k];
  if (p.variations > 1) body.variations = p.variations;
  if (job.kind === 'text' && p.samples != null) body.samples = p.samples;
  if (job.priority) body.priority = job.priority;
  return { template: toJson(body, p.seed != null ? String(p.seed) : null),
    files: { image: p.has_image ? 'image.png' : undefined, svg: p.has_svg ? 'start.svg' : undefined, rebuilt: true } };
}

export async function copyCurl() {
  try {
    await navigator.clipboard.writeText(el.curl.textContent);
    announce('curl command copied.');
  } catch (_) { // no clipboard (plain http on another host): select the text for Ctrl+C
    el.curl.closest('details').open = true;
    const range = document.createRange();
    range.selectNodeContents(el.curl);
    getSelection().removeAllRanges();
    getSelection().addRange(range);
    el.curl.focus();
    announce('No clipboard access: the command is selected, press Ctrl+C to copy it.');
  }
}
