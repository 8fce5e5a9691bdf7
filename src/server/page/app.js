// vectorfusion playground: a designer's front end to the public job API (openapi.yaml).
// Plain ES2020, no dependencies. The page is served with a strict CSP, so nothing here injects
// markup: text goes in with textContent, and SVGs (which may be hostile) are shown only as <img>
// with blob: URLs: an SVG in an <img> runs no script and loads nothing.
// The entry module: the recent jobs list and the wiring; the rest is in common.js, form.js and
// view.js (ES modules served from /js/).

import {
  el, TERMINAL, state, api, parseJson, clearError, showError, fmtAgo, jobName, h,
} from './js/common.js';
import {
  onKeySubmit, onKeyInput, forgetKey, updateMode, setFile, clearFile, onSubmit, reuseParams, copyCurl,
} from './js/form.js';
import { live, openJob, showVariation, loadPng, cancelJob } from './js/view.js';

// ---------- recent jobs ----------

export async function refreshJobs(explicit = false) {
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

export function renderJobs(jobs) {
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

export function markCurrentJob() {
  for (const li of el.jobs.children) {
    const b = li.querySelector('[data-action="open"]');
    if (state.view && li.dataset.id === state.view.id) b.setAttribute('aria-current', 'true');
    else b.removeAttribute('aria-current');
  }
}

export function onJobsClick(e) {
  const b = e.target.closest('button[data-action]');
  if (!b) return;
  const id = b.closest('li').dataset.id;
  if (b.dataset.action === 'cancel') { cancelJob(id); return; }
  clearError();
  openJob(id);
  el.canvas.focus();
}

export async function checkReady() {
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
