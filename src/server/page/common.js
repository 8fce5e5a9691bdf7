// The playground's shared pieces: element lookup, constants, the page state, the API client and
// small helpers (see app.js).

import { askForKey } from './form.js';

export const $ = (id) => document.getElementById(id);
// el.fooBar is the element with id "foo-bar" (looked up once, then cached).
export const el = new Proxy({}, {
  get: (cache, k) => cache[k] || (cache[k] = $(String(k).replace(/[A-Z]/g, (c) => `-${c.toLowerCase()}`))),
});
export const KEY_STORAGE = 'vectorfusion.apiKey';
export const U64_MAX = 18446744073709551615n;
export const TERMINAL = new Set(['succeeded', 'failed', 'cancelled']);
export const IMAGE_MARK = '@@VF_IMAGE@@'; // file contents in a request template (buildRequest, curlFor)
export const SVG_MARK = '@@VF_SVG@@';
export const STAGE_LABELS = { sample: 'Sampling images', rerank: 'Reranking samples',
  live: 'Tracing shapes (LIVE)', sds: 'Refining (score distillation)', done: 'Finishing' };
// The form control an API error's `field` names.
export const FIELD_INPUT = { caption: 'caption', style: 'style', preset: 'preset', method: 'method',
  paths: 'paths', seed: 'seed', steps: 'steps', samples: 'samples', priority: 'priority',
  retrieval: 'retrieval', image: 'file', svg: 'file', aspect: 'aspect', width: 'aspect',
  height: 'aspect', negative_prompt: 'negative-prompt', variations: 'variations', colors: 'colors',
  palette: 'palette', background: 'background', group: 'group', fill: 'fill' };
export const HEX_COLOUR = /^#([0-9a-f]{3}|[0-9a-f]{6})$/i;

export const state = {
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

export class ApiError extends Error {
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
export const localError = (field, reason) => new ApiError(0, 'invalid_field', field, reason);

// Every API error is {"error": {"code", "field", "reason"}}; anything else keeps the status line.
export async function errorFrom(res) {
  let code = `http_${res.status}`, field = null, reason = `${res.status} ${res.statusText}`.trim();
  try {
    const e = JSON.parse(await res.text()).error;
    if (e) { code = e.code || code; field = e.field ?? null; reason = e.reason || reason; }
  } catch (_) { /* not JSON */ }
  const ra = parseInt(res.headers.get('Retry-After') || '', 10);
  return new ApiError(res.status, code, field, reason, Number.isFinite(ra) ? ra : null);
}

// fetch() with the API key; throws ApiError for non-2xx answers and network failures.
export async function api(path, { method = 'GET', headers = {}, body, signal } = {}) {
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
export const parseJson = (text) => JSON.parse(text.replace(/"seed":(\d+)/g, '"seed":"$1"'));
export const prettyJson = (v) => JSON.stringify(v, null, 2).replace(/"seed": "(\d+)"/g, '"seed": $1');

// ---------- small helpers ----------

export const sleep = (ms, signal) => new Promise((resolve, reject) => {
  const t = setTimeout(resolve, ms);
  signal.addEventListener('abort', () => { clearTimeout(t); reject(new DOMException('aborted', 'AbortError')); }, { once: true });
});

export function announce(text) {
  el.announcer.textContent = '';
  setTimeout(() => { el.announcer.textContent = text; }, 50); // re-announce repeated messages
}

export function clearError() {
  el.error.textContent = '';
  document.querySelectorAll('[aria-invalid="true"]').forEach((n) => n.removeAttribute('aria-invalid'));
}
export function showError(err) {
  clearError();
  el.error.textContent = err instanceof ApiError ? err.describe() : String((err && err.message) || err);
  const target = err instanceof ApiError && err.field && $(FIELD_INPUT[err.field] || '');
  if (target) {
    target.setAttribute('aria-invalid', 'true');
    if (err.code === 'invalid_field') target.focus();
  }
}

export const fmtInt = (n) => Number(n).toLocaleString('en');
export const fmtMs = (ms) => (ms == null ? '–' : ms < 1000 ? `${ms} ms` : `${(ms / 1000).toFixed(1)} s`);
export function fmtBytes(n) {
  const kib = n / 1024;
  if (n < 1024) return `${fmtInt(n)} bytes`;
  return `${fmtInt(n)} bytes (${kib < 1024 ? `${kib.toFixed(1)} KiB` : `${(kib / 1024).toFixed(2)} MiB`})`;
}
export function fmtAgo(iso) {
  const s = Math.round((Date.parse(iso) - Date.now()) / 1000);
  if (!Number.isFinite(s)) return '';
  const rtf = new Intl.RelativeTimeFormat('en', { numeric: 'auto' });
  for (const [unit, size] of [['day', 86400], ['hour', 3600], ['minute', 60]]) {
    if (Math.abs(s) >= size) return rtf.format(Math.round(s / size), unit);
  }
  return rtf.format(s, 'second');
}
export const countPaths = (svg) => (svg.match(/<path[\s/>]/g) || []).length; // our SVGs: one <path> a shape
export const jobName = (job) => (job.params && job.params.caption) || (job.kind === 'vectorize' ? 'Image → SVG' : 'Untitled');
export function fileStem(job) {
  const slug = String((job.params && job.params.caption) || job.kind).toLowerCase()
    .replace(/[^a-z0-9]+/g, '-').replace(/^-+|-+$/g, '').slice(0, 40);
  return `${slug || job.kind}-${job.id.slice(0, 8)}`;
}
// h('button', {className, type, dataset: {…}, attrs: {…}}, ...children): builds an element;
// string children become text nodes (never markup).
export function h(tag, props = {}, ...children) {
  const { dataset, attrs, ...rest } = props;
  const n = Object.assign(document.createElement(tag), rest);
  Object.assign(n.dataset, dataset);
  for (const [k, v] of Object.entries(attrs || {})) if (v != null) n.setAttribute(k, v);
  n.append(...children);
  return n;
}
