// The playground's canvas: one viewed job, its progress over server-sent events, its result
// and variations, and the exports (see app.js).

import {
  el, TERMINAL, STAGE_LABELS, state, ApiError, api, parseJson, prettyJson, sleep, announce, clearError,
  showError, fmtInt, fmtMs, fmtBytes, countPaths, jobName, fileStem, h,
} from './common.js';
import { curlFor, templateFromJob } from './form.js';
import { refreshJobs, markCurrentJob } from '../app.js';

// ---------- the canvas: one viewed job ----------

export const live = (v) => state.view === v && !v.closed;

export function closeView() {
  const v = state.view;
  if (!v) return;
  v.closed = true;
  v.abort.abort();
  if (v.raf) cancelAnimationFrame(v.raf);
  if (v.snapshotUrl) URL.revokeObjectURL(v.snapshotUrl);
  v.urls.forEach((u) => URL.revokeObjectURL(u));
  state.view = null;
}

export function resetCanvas() {
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

export function openJob(id, initial) {
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
export function applyJob(v, job) {
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

export function setStage(stage, text) {
  const label = text || STAGE_LABELS[stage] || stage || 'Running';
  if (el.stage.textContent !== label) el.stage.textContent = label; // a live region: only on change
}

export function setProgress(stage, step, total, loss) {
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
export function showSnapshot(v, svg) {
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
export function renderRerank(r) {
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

export function renderParams(job) {
  const p = job.params, d = job.result && job.result.detail;
  const rows = [['Kind', job.kind]];
  if (p) {
    rows.push(['Caption', p.caption ?? '—'], ['Style', p.style], ['Method', p.method ?? '—'],
      ['Preset', p.preset], ['Paths', p.paths ?? '—'], ['Steps', p.steps ?? '—'], ['Samples', p.samples ?? '—'], ['Seed', p.seed],
      ['Started from', p.has_image ? 'an image' : p.has_svg ? 'an SVG' : 'noise'], ['Fill', p.fill || 'flat']);
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

export async function loadJobDetail(v) {
  try {
    const res = await api(`/jobs/${encodeURIComponent(v.id)}`, { signal: v.abort.signal });
    applyJob(v, parseJson(await res.text()));
  } catch (err) {
    if (err.name !== 'AbortError' && live(v)) showError(err);
  }
}

// Fetches bytes with the API key into a blob: URL owned by the view.
export async function fetchBlob(v, path, type) {
  const buf = await (await api(path, { signal: v.abort.signal })).arrayBuffer();
  const url = URL.createObjectURL(new Blob([buf], { type }));
  v.urls.add(url);
  return { url, buf };
}

export async function finish(v, job) {
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

export const variationCount = (v) => Math.max(1, v.variations.length);
export function disableLink(a) { a.removeAttribute('href'); a.setAttribute('aria-disabled', 'true'); }
export function setLink(a, url, name) { a.href = url; a.download = name; a.removeAttribute('aria-disabled'); }

// The API path of variation i's file (1-based; result/1 is result.svg), a PNG at the chosen size.
export function resultPath(v, i, ext) {
  const path = `/jobs/${encodeURIComponent(v.id)}/result/${i}.${ext}`;
  return ext === 'png' && el.pngSize.value ? `${path}?size=${el.pngSize.value}` : path;
}
export const variationStem = (v, i) => (variationCount(v) > 1 ? `${fileStem(v.job)}-${i}` : fileStem(v.job));

// Variation i's SVG (fetched once per view).
export async function variationSvg(v, i) {
  if (!v.svgs.has(i)) v.svgs.set(i, fetchBlob(v, resultPath(v, i, 'svg'), 'image/svg+xml'));
  return v.svgs.get(i);
}

// A thumbnail button per variation (none for a single result).
export function renderVariations(v) {
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
export async function showVariation(v, i) {
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
export async function loadPng(v) {
  const i = v.picked, size = el.pngSize.value;
  disableLink(el.downloadPng);
  const png = await fetchBlob(v, resultPath(v, i, 'png'), 'image/png');
  if (live(v) && v.picked === i && el.pngSize.value === size) {
    setLink(el.downloadPng, png.url, `${variationStem(v, i)}${size ? `-${size}px` : ''}.png`);
  }
}

// ---------- server-sent events over fetch() ----------

// One event of the stream; true when the stream is over (a terminal event).
export function onStreamEvent(v, ev) {
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
export async function readSse(body, onEvent, onId, onChunk) {
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
export async function streamEvents(v) {
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

export async function cancelJob(id) {
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
