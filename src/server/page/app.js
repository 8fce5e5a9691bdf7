// vectorfusion playground: a designer's front end to the public job API (openapi.yaml).
// Plain ES2020, no dependencies. The page is served with a strict CSP, so nothing here injects
// markup: text goes in with textContent, and SVGs (which may be hostile) are shown only as <img>
// with blob: URLs: an SVG in an <img> runs no script and loads nothing.
'use strict';
(() => {
  const $ = (id) => document.getElementById(id);
  // el.fooBar is the element with id "foo-bar" (looked up once, then cached).
  const el = new Proxy({}, {
    get: (cache, k) => cache[k] || (cache[k] = $(String(k).replace(/[A-Z]/g, (c) => `-${c.toLowerCase()}`))),
  });
  const KEY_STORAGE = 'vectorfusion.apiKey';
  const U64_MAX = 18446744073709551615n;
  const TERMINAL = new Set(['succeeded', 'failed', 'cancelled']);
  const IMAGE_MARK = '@@VF_IMAGE@@'; // file contents in a request template (buildRequest, curlFor)
  const SVG_MARK = '@@VF_SVG@@';
  const STAGE_LABELS = { sample: 'Sampling images', rerank: 'Reranking samples',
    live: 'Tracing shapes (LIVE)', sds: 'Refining (score distillation)', done: 'Finishing' };
  // The form control an API error's `field` names.
  const FIELD_INPUT = { caption: 'caption', style: 'style', preset: 'preset', method: 'method',
    paths: 'paths', seed: 'seed', steps: 'steps', samples: 'samples', priority: 'priority',
    retrieval: 'retrieval', image: 'file', svg: 'file', aspect: 'aspect', width: 'aspect',
    height: 'aspect', negative_prompt: 'negative-prompt', variations: 'variations', colors: 'colors',
    palette: 'palette', background: 'background', group: 'group' };
  const HEX_COLOUR = /^#([0-9a-f]{3}|[0-9a-f]{6})$/i;

  const state = {
    apiKey: sessionStorage.getItem(KEY_STORAGE) || '',
    file: null,          // {kind: 'image'|'svg', name, data (base64 or SVG text), previewUrl}
    fileReading: null,   // the promise of the file being read
    view: null,          // the job on the canvas (see openJob)
    submitting: false,
    requests: new Map(), // job id -> the request template submitted from this tab (for curl)
    jobsLoading: false, jobsAgain: false, jobsSig: '',
    keyFocused: false, authShown: false,
  };

  // ---------- API ----------

  class ApiError extends Error {
    constructor(status, code, field, reason, retryAfter = null) {
      super(reason);
      Object.assign(this, { status, code, field, reason, retryAfter });
    }
    describe() {
      let s = this.field ? `${this.field}: ${this.reason}` : this.reason;
      if (this.retryAfter != null) s += ` — retry in ${this.retryAfter} s`;
      return this.status ? `${s} (${this.code})` : s;
    }
  }
  const localError = (field, reason) => new ApiError(0, 'invalid_field', field, reason);

  // Every API error is {"error": {"code", "field", "reason"}}; anything else keeps the status line.
  async function errorFrom(res) {
    let code = `http_${res.status}`, field = null, reason = `${res.status} ${res.statusText}`.trim();
    try {
      const e = JSON.parse(await res.text()).error;
      if (e) { code = e.code || code; field = e.field ?? null; reason = e.reason || reason; }
    } catch (_) { /* not JSON */ }
    const ra = parseInt(res.headers.get('Retry-After') || '', 10);
    return new ApiError(res.status, code, field, reason, Number.isFinite(ra) ? ra : null);
  }

  // fetch() with the API key; throws ApiError for non-2xx answers and network failures.
  async function api(path, { method = 'GET', headers = {}, body, signal } = {}) {
    const h = new Headers(headers);
    if (state.apiKey) h.set('Authorization', `Bearer ${state.apiKey}`);
    let res;
    try {
      res = await fetch(path, { method, headers: h, body, signal, cache: 'no-store' });
    } catch (e) {
      if (e.name === 'AbortError') throw e;
      throw new ApiError(0, 'network', null, `Cannot reach the server (${e.message})`);
    }
    if (res.ok) return res;
    const err = await errorFrom(res);
    if (res.status === 401) askForKey();
    throw err;
  }

  // Seeds are u64: quote them before JSON.parse so no digit is lost to float rounding.
  // `"seed":<digits>` can only be a key and its value: quotes inside JSON strings are escaped.
  const parseJson = (text) => JSON.parse(text.replace(/"seed":(\d+)/g, '"seed":"$1"'));
  const prettyJson = (v) => JSON.stringify(v, null, 2).replace(/"seed": "(\d+)"/g, '"seed": $1');

  // ---------- small helpers ----------

  const sleep = (ms, signal) => new Promise((resolve, reject) => {
    const t = setTimeout(resolve, ms);
    signal.addEventListener('abort', () => { clearTimeout(t); reject(new DOMException('aborted', 'AbortError')); }, { once: true });
  });

  function announce(text) {
    el.announcer.textContent = '';
    setTimeout(() => { el.announcer.textContent = text; }, 50); // re-announce repeated messages
  }

  function clearError() {
    el.error.textContent = '';
    document.querySelectorAll('[aria-invalid="true"]').forEach((n) => n.removeAttribute('aria-invalid'));
  }
  function showError(err) {
    clearError();
    el.error.textContent = err instanceof ApiError ? err.describe() : String((err && err.message) || err);
    const target = err instanceof ApiError && err.field && $(FIELD_INPUT[err.field] || '');
    if (target) {
      target.setAttribute('aria-invalid', 'true');
      if (err.code === 'invalid_field') target.focus();
    }
  }

  const fmtInt = (n) => Number(n).toLocaleString('en');
  const fmtMs = (ms) => (ms == null ? '–' : ms < 1000 ? `${ms} ms` : `${(ms / 1000).toFixed(1)} s`);
  function fmtBytes(n) {
    const kib = n / 1024;
    if (n < 1024) return `${fmtInt(n)} bytes`;
    return `${fmtInt(n)} bytes (${kib < 1024 ? `${kib.toFixed(1)} KiB` : `${(kib / 1024).toFixed(2)} MiB`})`;
  }
  function fmtAgo(iso) {
    const s = Math.round((Date.parse(iso) - Date.now()) / 1000);
    if (!Number.isFinite(s)) return '';
    const rtf = new Intl.RelativeTimeFormat('en', { numeric: 'auto' });
    for (const [unit, size] of [['day', 86400], ['hour', 3600], ['minute', 60]]) {
      if (Math.abs(s) >= size) return rtf.format(Math.round(s / size), unit);
    }
    return rtf.format(s, 'second');
  }
  const countPaths = (svg) => (svg.match(/<path[\s/>]/g) || []).length; // our SVGs: one <path> a shape
  const jobName = (job) => (job.params && job.params.caption) || (job.kind === 'vectorize' ? 'Image → SVG' : 'Untitled');
  function fileStem(job) {
    const slug = String((job.params && job.params.caption) || job.kind).toLowerCase()
      .replace(/[^a-z0-9]+/g, '-').replace(/^-+|-+$/g, '').slice(0, 40);
    return `${slug || job.kind}-${job.id.slice(0, 8)}`;
  }
  // h('button', {className, type, dataset: {…}, attrs: {…}}, ...children): builds an element;
  // string children become text nodes (never markup).
  function h(tag, props = {}, ...children) {
    const { dataset, attrs, ...rest } = props;
    const n = Object.assign(document.createElement(tag), rest);
    Object.assign(n.dataset, dataset);
    for (const [k, v] of Object.entries(attrs || {})) if (v != null) n.setAttribute(k, v);
    n.append(...children);
    return n;
  }

  // ---------- API key ----------

  function askForKey() {
    el.keyForm.hidden = false;
    if (!state.keyFocused) { state.keyFocused = true; el.apiKey.focus(); }
  }

  function onKeySubmit(e) {
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
  function onKeyInput() {
    const key = el.apiKey.value.trim();
    if (key && !/^[\x21-\x7e]+$/.test(key)) return;
    state.apiKey = key;
    if (key) sessionStorage.setItem(KEY_STORAGE, key);
    else sessionStorage.removeItem(KEY_STORAGE);
  }

  function forgetKey() {
    state.apiKey = '';
    sessionStorage.removeItem(KEY_STORAGE);
    el.apiKey.value = '';
    announce('API key forgotten.');
    el.apiKey.focus();
  }

  // ---------- the form ----------

  function updateMode() {
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

  const readDataUrl = (file) => new Promise((resolve, reject) => {
    const r = new FileReader();
    r.onload = () => resolve(String(r.result));
    r.onerror = () => reject(r.error);
    r.readAsDataURL(file);
  });

  async function setFile(file) {
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

  function clearFile() {
    if (state.file) URL.revokeObjectURL(state.file.previewUrl);
    state.file = null;
    el.filePreview.removeAttribute('src');
    el.fileChosen.hidden = true;
    updateMode();
  }

  // An optional integer input; undefined when empty.
  function intField(id, min, max) {
    if ($(id).validity.badInput) throw localError(id, `must be a whole number from ${min} to ${max}`);
    const raw = $(id).value.trim();
    if (raw === '') return undefined;
    const n = Number(raw);
    if (!Number.isInteger(n) || n < min || n > max) throw localError(id, `must be a whole number from ${min} to ${max}`);
    return n;
  }

  function readSeed() {
    const raw = el.seed.value.trim();
    if (raw === '') return null;
    if (!/^\d{1,40}$/.test(raw) || BigInt(raw) > U64_MAX) throw localError('seed', `must be a whole number from 0 to ${U64_MAX}`);
    return BigInt(raw).toString(); // without leading zeros, which JSON forbids
  }

  // JSON text of a body, the seed spliced in as digits (JSON.stringify cannot write a u64).
  const toJson = (body, seed) => {
    const s = JSON.stringify(body);
    return seed == null ? s : `${s.slice(0, -1)},"seed":${seed}}`;
  };

  // The request the form describes: {json, template, files}. `template` is the same JSON with the
  // file's contents replaced by a marker, for the curl command.
  function buildRequest() {
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
  // background, group; the defaults are left out.
  function colourFields() {
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
    return out;
  }

  // The form's colour controls showing `p`'s colors, palette, background and group.
  function setColourFields(p) {
    el.colors.value = p.colors ?? '';
    el.palette.value = (p.palette || []).join(' ');
    const bg = p.background || 'auto';
    el.background.value = bg === 'auto' || bg === 'transparent' ? bg : 'color';
    if (el.background.value === 'color') el.backgroundColor.value = bg;
    el.backgroundColor.hidden = el.background.value !== 'color';
    el.group.value = p.group === 'color' ? 'color' : 'none';
  }

  async function onSubmit(e) {
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
  function reuseParams() {
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

  const shq = (s) => `'${String(s).replace(/'/g, "'\\''")}'`;

  // The POST as a shell command. File contents are elided: the command reads them from the file.
  function curlFor(template, files) {
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
  function templateFromJob(job) {
    const p = job.params || {};
    const body = { kind: job.kind };
    if (p.caption != null) body.caption = p.caption;
    if (p.has_image) body.image = IMAGE_MARK;
    if (p.has_svg) body.svg = SVG_MARK;
    for (const k of ['style', 'preset', 'method', 'paths', 'steps', 'aspect', 'width', 'height', 'negative_prompt',
      'colors', 'palette', 'background', 'group']) if (p[k] != null) body[k] = p[k];
    if (p.variations > 1) body.variations = p.variations;
    if (job.kind === 'text' && p.samples != null) body.samples = p.samples;
    if (job.priority) body.priority = job.priority;
    return { template: toJson(body, p.seed != null ? String(p.seed) : null),
      files: { image: p.has_image ? 'image.png' : undefined, svg: p.has_svg ? 'start.svg' : undefined, rebuilt: true } };
  }

  async function copyCurl() {
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

  // ---------- the canvas: one viewed job ----------

  const live = (v) => state.view === v && !v.closed;

  function closeView() {
    const v = state.view;
    if (!v) return;
    v.closed = true;
    v.abort.abort();
    if (v.raf) cancelAnimationFrame(v.raf);
    if (v.snapshotUrl) URL.revokeObjectURL(v.snapshotUrl);
    v.urls.forEach((u) => URL.revokeObjectURL(u));
    state.view = null;
  }

  function resetCanvas() {
    for (const img of [el.snapshot, el.result]) img.removeAttribute('src');
    [el.downloadSvg, el.downloadPng, el.downloadPdf].forEach(disableLink);
    for (const n of [el.snapshot, el.resultView, el.samplesView, el.paramsView, el.detailBox, el.variationPicker]) n.hidden = true;
    el.variationList.textContent = '';
    el.empty.hidden = el.liveView.hidden = false;
    el.sampleList.textContent = el.step.textContent = el.connection.textContent = '';
    el.loss.textContent = el.pathCount.textContent = el.snapshotN.textContent = el.attempt.textContent = '–';
    el.stage.textContent = 'Connecting…';
    el.progress.max = 1;
    el.progress.value = 0;
  }

  function openJob(id, initial) {
    closeView();
    const v = { id, abort: new AbortController(), urls: new Set(), snapshotUrl: null, pendingSvg: null,
      raf: 0, lastEventId: null, job: null, finished: false, closed: false,
      variations: [], picked: 0, svgs: new Map() };
    state.view = v;
    resetCanvas();
    if (initial) applyJob(v, initial);
    markCurrentJob();
    loadJobDetail(v); // a running job's rerank scores come from GET /jobs/{id} only
    streamEvents(v);
  }

  // Shows a job object (from POST, GET, or a state/done/failed/cancelled event).
  function applyJob(v, job) {
    if (!live(v) || (v.finished && !TERMINAL.has(job.status))) return; // a stale GET after the end
    job = v.job = Object.assign(v.job || {}, job); // GET adds result, rerank, attempt_history
    const cancelling = job.cancel_requested && !TERMINAL.has(job.status);
    el.jobTitle.textContent = `${jobName(job)} · ${job.kind} · ${job.id}`;
    el.statusBadge.hidden = false;
    el.statusBadge.textContent = cancelling ? 'cancelling' : job.status;
    el.statusBadge.className = `badge status-${job.status}`;
    el.cancel.hidden = TERMINAL.has(job.status) || job.cancel_requested;
    el.attempt.textContent = job.max_attempts ? `${job.attempts} of ${job.max_attempts}` : String(job.attempts ?? '–');
    if (job.status === 'queued') {
      setStage(null, job.attempts > 0 ? 'Queued for a retry' : 'Queued — waiting for a worker');
      el.progress.removeAttribute('value'); // indeterminate
    } else if (job.status === 'running' && job.progress) {
      setProgress(job.progress.stage, job.progress.step, job.progress.total, job.progress.loss);
    }
    if (job.rerank) renderRerank(job.rerank);
    if (job.result && job.result.paths != null) {
      el.pathCount.textContent = fmtInt(job.result.paths);
      el.resultPaths.textContent = `${fmtInt(job.result.paths)} paths`;
    }
    renderParams(job);
  }

  function setStage(stage, text) {
    const label = text || STAGE_LABELS[stage] || stage || 'Running';
    if (el.stage.textContent !== label) el.stage.textContent = label; // a live region: only on change
  }

  function setProgress(stage, step, total, loss) {
    setStage(stage);
    if (total > 0) {
      el.progress.max = total;
      el.progress.value = Math.min(step, total);
      el.step.textContent = `${fmtInt(step)} / ${fmtInt(total)}`;
    } else {
      el.progress.removeAttribute('value');
      el.step.textContent = step ? `step ${fmtInt(step)}` : '';
    }
    if (loss != null && Number.isFinite(loss)) el.loss.textContent = Number(loss).toPrecision(4);
  }

  // One image update per frame at most (a reconnect may replay hundreds of snapshots).
  function showSnapshot(v, svg) {
    v.pendingSvg = svg;
    if (v.raf) return;
    v.raf = requestAnimationFrame(() => {
      v.raf = 0;
      if (!live(v) || v.pendingSvg == null) return;
      const old = v.snapshotUrl;
      v.snapshotUrl = URL.createObjectURL(new Blob([v.pendingSvg], { type: 'image/svg+xml' }));
      v.pendingSvg = null;
      el.snapshot.src = v.snapshotUrl;
      el.snapshot.hidden = false;
      el.empty.hidden = true;
      if (old) URL.revokeObjectURL(old);
    });
  }

  // The K samples' rerank: the progress event of stage rerank ({scorer, scores, chosen,
  // samples, sources}) or GET /jobs/{id} ({scorer, scores, chosen, samples}). Scores only: the
  // API does not send the sampled images.
  function renderRerank(r) {
    const chosen = r.chosen;
    const scores = Array.isArray(r.scores) ? r.scores : [];
    const lo = Math.min(...scores), hi = Math.max(...scores);
    el.samplesView.hidden = false;
    el.samplesNote.textContent = `${r.scorer ? `Scored by ${r.scorer}` : 'No scorer configured: the first sample is kept'}`
      + ` · ${r.samples ?? scores.length} samples · the API streams the scores, not the sampled images.`;
    el.sampleList.textContent = '';
    for (let i = 0; i < Math.max(scores.length, r.samples || 0); i++) {
      const li = h('li', { className: i === chosen ? 'sample chosen' : 'sample' }, h('span', { className: 'sample-index' }, `#${i + 1}`));
      if (i < scores.length) {
        // A <meter> for the bar (no inline styles under the CSP); the lowest bar stays visible.
        li.append(h('meter', { min: lo - (hi - lo || 1) * 0.1, max: hi, value: scores[i], attrs: { 'aria-label': `Score of sample ${i + 1}` } }),
          h('span', { className: 'sample-score' }, scores[i].toFixed(4)));
      }
      const src = r.sources && r.sources[i];
      if (r.sources) li.append(h('span', { className: 'sample-source' }, src ? `from ${src.set}/${src.name} (${src.license})` : 'from noise'));
      if (i === chosen) li.append(h('span', { className: 'badge status-succeeded' }, 'kept'));
      el.sampleList.append(li);
    }
  }

  function renderParams(job) {
    const p = job.params, d = job.result && job.result.detail;
    const rows = [['Kind', job.kind]];
    if (p) {
      rows.push(['Caption', p.caption ?? '—'], ['Style', p.style], ['Method', p.method ?? '—'],
        ['Preset', p.preset], ['Paths', p.paths ?? '—'], ['Steps', p.steps ?? '—'], ['Samples', p.samples ?? '—'], ['Seed', p.seed],
        ['Started from', p.has_image ? 'an image' : p.has_svg ? 'an SVG' : 'noise']);
      // The run plan the job runs with (every number, resolved when it was accepted).
      const t = p.plan && p.plan.text, v = p.plan && p.plan.vectorize;
      if (t) {
        rows.push(['Size', t.canvas ? `${t.canvas.width}×${t.canvas.height} px (sampled at ${t.canvas.sample_width}×${t.canvas.sample_height})` : `${t.size} px`],
          ['Model', `${t.model.name} (${t.model.encoder})`]);
        if (t.negative_prompt) rows.push(['Negative prompt', t.negative_prompt]);
        if (t.sample) rows.push(['Sampler', `K=${t.sample.samples}, ${t.sample.steps} steps, retrieval ${t.sample.retrieval ? 'on' : 'off'}`]);
        if (t.sds) rows.push(['SDS', `${t.sds.steps} steps, guidance ${t.sds.guidance}, t ${t.sds.t_min}–${t.sds.t_max}`]);
      }
      if (v) rows.push(['LIVE', `${v.size} px, ${v.iters_per_stage} iterations per stage`]);
    }
    rows.push(['Priority', job.priority ?? 0], ['Queued for', fmtMs(job.queued_ms)], ['Ran for', fmtMs(job.run_ms)]);
    if (d && d.seconds != null) rows.push(['Compute', `${Number(d.seconds).toFixed(1)} s`]);
    if (d && d.psnr != null) rows.push(['PSNR', `${Number(d.psnr).toFixed(2)} dB`]);
    if (job.error) rows.push(['Error', `${job.error.code}: ${job.error.message}`]);
    el.params.textContent = '';
    for (const [k, val] of rows) el.params.append(h('tr', {}, h('th', { scope: 'row' }, k), h('td', {}, String(val))));
    el.paramsView.hidden = false;
    el.detailBox.hidden = !d;
    if (d) el.detailJson.textContent = prettyJson(d);
    el.jobJson.textContent = prettyJson(job);
    const req = state.requests.get(job.id) || templateFromJob(job);
    el.curl.textContent = curlFor(req.template, req.files);
  }

  async function loadJobDetail(v) {
    try {
      const res = await api(`/jobs/${encodeURIComponent(v.id)}`, { signal: v.abort.signal });
      applyJob(v, parseJson(await res.text()));
    } catch (err) {
      if (err.name !== 'AbortError' && live(v)) showError(err);
    }
  }

  // Fetches bytes with the API key into a blob: URL owned by the view.
  async function fetchBlob(v, path, type) {
    const buf = await (await api(path, { signal: v.abort.signal })).arrayBuffer();
    const url = URL.createObjectURL(new Blob([buf], { type }));
    v.urls.add(url);
    return { url, buf };
  }

  async function finish(v, job) {
    v.finished = true;
    el.cancel.hidden = true;
    el.connection.textContent = '';
    refreshJobs();
    const detail = loadJobDetail(v); // result.paths, result.detail, result.variations, rerank, error
    if (job.status !== 'succeeded') {
      const e = job.error || {};
      setStage(null, job.status === 'failed' ? 'Failed' : 'Cancelled');
      if (job.status === 'failed') showError(`The job failed: ${e.message || 'no reason given'}${e.code ? ` (${e.code})` : ''}`);
      else announce('The job was cancelled.');
      return;
    }
    setStage(null, 'Done');
    el.progress.max = 1;
    el.progress.value = 1;
    try {
      await detail; // result.variations
      if (!live(v)) return;
      v.variations = (v.job.result && v.job.result.variations) || [];
      el.liveView.hidden = true;
      el.resultView.hidden = false;
      renderVariations(v);
      await showVariation(v, 1);
      if (!live(v)) return;
      const n = variationCount(v);
      announce(`Done: ${n > 1 ? `${n} variations, ` : ''}${el.resultPaths.textContent}, ${el.resultBytes.textContent}.`);
    } catch (err) {
      if (err.name !== 'AbortError' && live(v)) showError(err);
    }
  }

  // ---------- the result: variations and export ----------

  const variationCount = (v) => Math.max(1, v.variations.length);
  function disableLink(a) { a.removeAttribute('href'); a.setAttribute('aria-disabled', 'true'); }
  function setLink(a, url, name) { a.href = url; a.download = name; a.removeAttribute('aria-disabled'); }

  // The API path of variation i's file (1-based; result/1 is result.svg), a PNG at the chosen size.
  function resultPath(v, i, ext) {
    const path = `/jobs/${encodeURIComponent(v.id)}/result/${i}.${ext}`;
    return ext === 'png' && el.pngSize.value ? `${path}?size=${el.pngSize.value}` : path;
  }
  const variationStem = (v, i) => (variationCount(v) > 1 ? `${fileStem(v.job)}-${i}` : fileStem(v.job));

  // Variation i's SVG (fetched once per view).
  async function variationSvg(v, i) {
    if (!v.svgs.has(i)) v.svgs.set(i, fetchBlob(v, resultPath(v, i, 'svg'), 'image/svg+xml'));
    return v.svgs.get(i);
  }

  // A thumbnail button per variation (none for a single result).
  function renderVariations(v) {
    const n = variationCount(v);
    el.variationList.textContent = '';
    el.variationPicker.hidden = n < 2;
    if (n < 2) return;
    for (const info of v.variations) {
      const i = info.variation;
      const img = h('img', { alt: '' });
      const score = info.score != null ? ` · ${Number(info.score).toFixed(3)}` : '';
      el.variationList.append(h('li', {}, h('button', { type: 'button', className: 'variation',
        dataset: { i: String(i) }, attrs: { 'aria-pressed': 'false', 'aria-label': `Variation ${i}${score}, ${info.paths} paths` } },
      h('span', { className: 'thumb checker' }, img), h('span', { className: 'variation-n' }, `#${i}${score}`))));
      variationSvg(v, i).then((s) => { if (live(v)) img.src = s.url; }, () => {});
    }
  }

  // Shows variation i: the picture, its paths and bytes, and its SVG, PNG and PDF downloads.
  async function showVariation(v, i) {
    v.picked = i;
    for (const b of el.variationList.querySelectorAll('button')) b.setAttribute('aria-pressed', String(b.dataset.i === String(i)));
    [el.downloadSvg, el.downloadPng, el.downloadPdf].forEach(disableLink);
    const svg = await variationSvg(v, i);
    if (!live(v) || v.picked !== i) return;
    const stem = variationStem(v, i);
    // The link's href is a blob of exactly the bytes the API returned.
    el.result.src = svg.url;
    setLink(el.downloadSvg, svg.url, `${stem}.svg`);
    el.resultBytes.textContent = fmtBytes(svg.buf.byteLength);
    const info = v.variations.find((x) => x.variation === i);
    // Decoded from the bytes (fetching the blob: URL would need connect-src blob:).
    const paths = info ? info.paths : countPaths(new TextDecoder().decode(svg.buf));
    const n = variationCount(v);
    el.resultPaths.textContent = `${n > 1 ? `Variation ${i} of ${n} · ` : ''}${fmtInt(paths)} paths`;
    el.pathCount.textContent = fmtInt(paths);
    const pdf = fetchBlob(v, resultPath(v, i, 'pdf'), 'application/pdf').then((f) => {
      if (live(v) && v.picked === i) setLink(el.downloadPdf, f.url, `${stem}.pdf`);
    });
    await Promise.all([loadPng(v), pdf]);
  }

  // The PNG download of the picked variation at the chosen size.
  async function loadPng(v) {
    const i = v.picked, size = el.pngSize.value;
    disableLink(el.downloadPng);
    const png = await fetchBlob(v, resultPath(v, i, 'png'), 'image/png');
    if (live(v) && v.picked === i && el.pngSize.value === size) {
      setLink(el.downloadPng, png.url, `${variationStem(v, i)}${size ? `-${size}px` : ''}.png`);
    }
  }

  // ---------- server-sent events over fetch() ----------

  // One event of the stream; true when the stream is over (a terminal event).
  function onStreamEvent(v, ev) {
    if (!live(v)) return true;
    try {
      if (ev.type === 'state') applyJob(v, parseJson(ev.data));
      else if (ev.type === 'progress') {
        const p = JSON.parse(ev.data), d = p.detail; // {stage, step, total, fraction, loss, detail}
        setProgress(p.stage, p.step, p.total, p.loss);
        if (d && typeof d.paths === 'number') el.pathCount.textContent = fmtInt(d.paths); // LIVE
        if (d && p.stage === 'rerank' && Array.isArray(d.scores)) renderRerank(d);
      } else if (ev.type === 'snapshot') {
        const s = JSON.parse(ev.data); // {n, stage, step, svg}
        el.snapshotN.textContent = `#${s.n} · ${s.stage} ${s.step}`;
        el.pathCount.textContent = fmtInt(countPaths(s.svg));
        showSnapshot(v, s.svg);
      } else if (ev.type === 'done' || ev.type === 'failed' || ev.type === 'cancelled') {
        const job = parseJson(ev.data);
        applyJob(v, job);
        finish(v, job);
        return true;
      }
    } catch (e) {
      console.warn('vectorfusion: ignoring a malformed event', ev.type, e);
    }
    return false;
  }

  // Parses text/event-stream from a fetch() body: the EventSource algorithm by hand, because
  // EventSource cannot send an Authorization header. Resolves true after a terminal event, false
  // when the server closed the stream.
  async function readSse(body, onEvent, onId, onChunk) {
    const reader = body.getReader();
    const decoder = new TextDecoder(); // UTF-8; `stream: true` keeps characters split by chunks
    let buf = '', pendingCR = false, first = true, data = [], type = '', id = null;
    const line = (l) => {
      if (l === '') { // a blank line dispatches the event
        if (id != null) onId(id);
        const ev = data.length ? { type: type || 'message', data: data.join('\n') } : null;
        data = []; type = ''; id = null;
        return ev ? onEvent(ev) : false;
      }
      if (l[0] === ':') return false; // a comment: the keep-alive heartbeat
      const i = l.indexOf(':');
      const field = i < 0 ? l : l.slice(0, i);
      let value = i < 0 ? '' : l.slice(i + 1);
      if (value[0] === ' ') value = value.slice(1);
      if (field === 'event') type = value;
      else if (field === 'data') data.push(value);
      else if (field === 'id' && !value.includes('\0')) id = value;
      return false; // `retry` and unknown fields are ignored: we back off ourselves
    };
    try {
      for (;;) {
        const { value, done } = await reader.read();
        onChunk();
        let text = done ? decoder.decode() : decoder.decode(value, { stream: true });
        if (first && text) { first = false; if (text[0] === '\ufeff') text = text.slice(1); }
        // CR, LF and CRLF all end a line, and a CRLF may be split between two chunks.
        if (pendingCR && text[0] === '\n') text = text.slice(1);
        if (text) pendingCR = text.endsWith('\r');
        const from = buf.length; // the kept tail holds no line end: search only the new text
        buf += text.replace(/\r\n?/g, '\n');
        let pos = 0;
        for (let nl = buf.indexOf('\n', from); nl >= 0; nl = buf.indexOf('\n', pos)) {
          const l = buf.slice(pos, nl);
          pos = nl + 1;
          if (line(l)) return true;
        }
        buf = buf.slice(pos);
        if (done) return false; // an unterminated last event is dropped, as EventSource does
      }
    } finally {
      reader.cancel().catch(() => {});
    }
  }

  // Follows a job's events until it ends, reconnecting with Last-Event-ID (the last snapshot's
  // number) and exponential backoff.
  async function streamEvents(v) {
    let attempt = 0;
    while (live(v) && !v.finished) {
      const conn = new AbortController();
      const stop = () => conn.abort();
      v.abort.signal.addEventListener('abort', stop, { once: true });
      // Heartbeats come every few seconds: a silent minute means a dead connection.
      let watchdog = 0;
      const pet = () => { clearTimeout(watchdog); watchdog = setTimeout(stop, 60000); };
      try {
        const headers = { Accept: 'text/event-stream' };
        if (v.lastEventId != null) headers['Last-Event-ID'] = v.lastEventId;
        pet();
        const res = await api(`/jobs/${encodeURIComponent(v.id)}/events`, { headers, signal: conn.signal });
        el.connection.textContent = 'Live';
        const over = await readSse(res.body, (ev) => { attempt = 0; return onStreamEvent(v, ev); },
          (id) => { v.lastEventId = id; }, pet);
        if (over) return;
      } catch (err) {
        if (!live(v)) return;
        if (err instanceof ApiError && err.status >= 400 && err.status < 500 && err.status !== 429) {
          showError(err); // 401 (the key form is shown), 404 (unknown or expired job): stop
          el.connection.textContent = '';
          return;
        }
        if (err instanceof ApiError && err.retryAfter != null) { // 429 busy
          el.connection.textContent = `Server busy, retrying in ${err.retryAfter} s…`;
          try { await sleep(err.retryAfter * 1000, v.abort.signal); } catch (_) { return; }
          continue;
        }
        // Network error, 5xx, a dropped or stalled stream: back off and reconnect below.
      } finally {
        clearTimeout(watchdog);
        v.abort.signal.removeEventListener('abort', stop);
      }
      if (!live(v) || v.finished) return;
      const delay = Math.min(15000, 500 * 2 ** attempt) * (0.75 + Math.random() * 0.5);
      attempt = Math.min(attempt + 1, 10);
      el.connection.textContent = `Connection lost, reconnecting in ${Math.ceil(delay / 1000)} s…`;
      try { await sleep(delay, v.abort.signal); } catch (_) { return; }
    }
  }

  async function cancelJob(id) {
    clearError();
    try {
      const job = parseJson(await (await api(`/jobs/${encodeURIComponent(id)}`, { method: 'DELETE' })).text());
      announce(job.status === 'cancelled' ? 'Job cancelled.' : 'Cancel requested: the job stops at its next step.');
      if (state.view && state.view.id === id) applyJob(state.view, job);
    } catch (err) {
      showError(err);
    }
    refreshJobs();
  }

  // ---------- recent jobs ----------

  async function refreshJobs(explicit = false) {
    if (state.jobsLoading) { state.jobsAgain = true; return; }
    state.jobsLoading = true;
    try {
      const list = parseJson(await (await api('/jobs?limit=25')).text());
      renderJobs(list.jobs || []);
      el.jobsStatus.textContent = list.jobs && list.jobs.length ? '' : 'No jobs yet.';
      state.authShown = false;
    } catch (err) {
      el.jobsStatus.textContent = `Could not load the jobs: ${err.message}`;
      // Background refreshes do not flood the alert region: explicit loads and a first 401 do.
      if (explicit || (err.status === 401 && !state.authShown)) showError(err);
      if (err.status === 401) state.authShown = true;
    } finally {
      state.jobsLoading = false;
      if (state.jobsAgain) { state.jobsAgain = false; refreshJobs(); }
    }
  }

  function renderJobs(jobs) {
    const current = state.view ? state.view.id : '';
    const sig = JSON.stringify([current, Math.floor(Date.now() / 60000),
      jobs.map((j) => [j.id, j.status, j.stage, j.progress && j.progress.fraction, j.cancel_requested])]);
    if (sig === state.jobsSig) return; // unchanged: leave the DOM (and focus) alone
    state.jobsSig = sig;
    // Rebuilding drops keyboard focus: remember which button had it.
    const f = document.activeElement;
    const li0 = f && f.closest && f.closest('#jobs li');
    const keep = li0 ? { id: li0.dataset.id, action: f.dataset.action } : null;
    el.jobs.textContent = '';
    for (const j of jobs) {
      const cancelling = j.cancel_requested && !TERMINAL.has(j.status);
      let meta = ` ${j.kind}`;
      if (j.status === 'running' && j.progress) meta += ` · ${j.stage || ''} ${Math.round((j.progress.fraction || 0) * 100)}%`;
      const li = h('li', { className: 'job', dataset: { id: j.id } },
        h('button', { className: 'job-open', type: 'button', dataset: { action: 'open' }, attrs: { 'aria-current': j.id === current ? 'true' : null } },
          h('span', { className: 'job-name' }, jobName(j)),
          h('span', { className: 'job-meta' }, h('span', { className: `badge status-${j.status}` }, cancelling ? 'cancelling' : j.status),
            `${meta} · ${fmtAgo(j.created_at)}`)));
      if (!TERMINAL.has(j.status) && !j.cancel_requested) {
        li.append(h('button', { className: 'ghost small job-cancel', type: 'button', dataset: { action: 'cancel' },
          attrs: { 'aria-label': `Cancel “${jobName(j)}”` } }, 'Cancel'));
      }
      el.jobs.append(li);
    }
    if (keep) {
      const li = [...el.jobs.children].find((n) => n.dataset.id === keep.id);
      const b = li && (li.querySelector(`[data-action="${keep.action}"]`) || li.querySelector('[data-action="open"]'));
      if (b) b.focus();
    }
  }

  function markCurrentJob() {
    for (const li of el.jobs.children) {
      const b = li.querySelector('[data-action="open"]');
      if (state.view && li.dataset.id === state.view.id) b.setAttribute('aria-current', 'true');
      else b.removeAttribute('aria-current');
    }
  }

  function onJobsClick(e) {
    const b = e.target.closest('button[data-action]');
    if (!b) return;
    const id = b.closest('li').dataset.id;
    if (b.dataset.action === 'cancel') { cancelJob(id); return; }
    clearError();
    openJob(id);
    el.canvas.focus();
  }

  async function checkReady() {
    try {
      const r = await (await fetch('/readyz', { cache: 'no-store' })).json(); // no key needed
      const ok = r.status === 'ready';
      el.serverStatus.textContent = ok ? `Ready · ${r.workers} worker${r.workers === 1 ? '' : 's'}`
        : `Not ready${r.shutting_down ? ' (shutting down)' : ''}`;
      el.serverStatus.className = `server-status ${ok ? 'ok' : 'bad'}`;
      el.textModelsNote.hidden = r.text_jobs_accepted !== false;
      el.textModelsNote.textContent = `Caption jobs are off on this server (no text models): ${r.text_models || ''} `
        + 'Vectorizing an image still works.';
    } catch (_) {
      el.serverStatus.textContent = 'Server unreachable';
      el.serverStatus.className = 'server-status bad';
    }
  }

  // ---------- wiring ----------

  function init() {
    el.keyForm.hidden = !state.apiKey;
    el.apiKey.value = state.apiKey;
    el.keyForm.addEventListener('submit', onKeySubmit);
    el.apiKey.addEventListener('input', onKeyInput);
    el.apiKeyForget.addEventListener('click', forgetKey);
    el.jobForm.addEventListener('submit', onSubmit);
    el.caption.addEventListener('input', updateMode);
    el.file.addEventListener('change', () => { state.fileReading = setFile(el.file.files[0]); });
    el.fileClear.addEventListener('click', () => { el.file.value = ''; clearFile(); el.file.focus(); });
    el.seedRandom.addEventListener('click', () => {
      const w = crypto.getRandomValues(new Uint32Array(2));
      el.seed.value = ((BigInt(w[0]) << 32n) | BigInt(w[1])).toString();
    });
    // Drag and drop onto the zone; a drop anywhere else must not navigate away from the page.
    for (const t of ['dragover', 'drop']) window.addEventListener(t, (e) => e.preventDefault());
    const zone = el.dropzone;
    zone.addEventListener('dragover', (e) => { e.dataTransfer.dropEffect = 'copy'; zone.classList.add('dragging'); });
    zone.addEventListener('dragleave', (e) => { if (!zone.contains(e.relatedTarget)) zone.classList.remove('dragging'); });
    zone.addEventListener('drop', (e) => {
      zone.classList.remove('dragging');
      const files = e.dataTransfer && e.dataTransfer.files;
      if (!files || !files.length) return;
      try { el.file.files = files; } catch (_) { /* read-only in old browsers */ }
      state.fileReading = setFile(files[0]);
    });
    el.cancel.addEventListener('click', async () => {
      if (!state.view) return;
      await cancelJob(state.view.id);
      if (el.cancel.hidden) el.canvas.focus(); // the focused button just disappeared
    });
    el.copyCurl.addEventListener('click', copyCurl);
    el.reuse.addEventListener('click', reuseParams);
    el.jobs.addEventListener('click', onJobsClick);
    el.jobsRefresh.addEventListener('click', () => { clearError(); refreshJobs(true); });
    // Download links without their blob yet do nothing (and, without href, are not focusable).
    el.background.addEventListener('change', () => { el.backgroundColor.hidden = el.background.value !== 'color'; });
    el.variationList.addEventListener('click', (e) => {
      const b = e.target.closest('button[data-i]');
      if (!b || !state.view) return;
      const v = state.view;
      showVariation(v, Number(b.dataset.i)).catch((err) => { if (err.name !== 'AbortError' && live(v)) showError(err); });
    });
    el.pngSize.addEventListener('change', () => {
      const v = state.view;
      if (v && v.picked) loadPng(v).catch((err) => { if (err.name !== 'AbortError' && live(v)) showError(err); });
    });
    for (const a of [el.downloadSvg, el.downloadPng, el.downloadPdf]) {
      a.addEventListener('click', (e) => { if (a.getAttribute('aria-disabled') === 'true') e.preventDefault(); });
    }
    setInterval(() => { if (!document.hidden) refreshJobs(); }, 5000);
    setInterval(() => { if (!document.hidden) checkReady(); }, 30000);
    document.addEventListener('visibilitychange', () => { if (!document.hidden) refreshJobs(); });
    updateMode();
    checkReady();
    refreshJobs(true);
  }

  if (document.readyState === 'loading') document.addEventListener('DOMContentLoaded', init);
  else init();
})();
