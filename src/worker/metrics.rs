//! Process metrics, rendered in the Prometheus text exposition format by `GET /metrics`.

use crate::store::FailureCode;
use std::collections::BTreeMap;
use std::fmt::Write;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

/// Histogram bucket upper bounds, seconds.
const SECONDS_BUCKETS: [f64; 12] = [
    0.005, 0.01, 0.05, 0.1, 0.5, 1.0, 5.0, 10.0, 30.0, 60.0, 300.0, 1800.0,
];

/// Bucket bounds for HTTP request durations, seconds.
const HTTP_BUCKETS: [f64; 12] = [
    0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 5.0,
];

#[derive(Clone, Debug)]
struct Histogram {
    bounds: &'static [f64],
    counts: Vec<u64>,
    count: u64,
    sum: f64,
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram::new(&SECONDS_BUCKETS)
    }
}

impl Histogram {
    fn new(bounds: &'static [f64]) -> Self {
        Histogram {
            bounds,
            counts: vec![0; bounds.len()],
            count: 0,
            sum: 0.0,
        }
    }

    fn observe(&mut self, v: f64) {
        for (i, b) in self.bounds.iter().enumerate() {
            if v <= *b {
                self.counts[i] += 1;
            }
        }
        self.count += 1;
        self.sum += v;
    }

    fn render(&self, out: &mut String, name: &str, labels: &str) {
        let sep = if labels.is_empty() { "" } else { "," };
        for (i, b) in self.bounds.iter().enumerate() {
            let _ = writeln!(
                out,
                "{name}_bucket{{{labels}{sep}le=\"{b}\"}} {}",
                self.counts[i]
            );
        }
        let _ = writeln!(
            out,
            "{name}_bucket{{{labels}{sep}le=\"+Inf\"}} {}",
            self.count
        );
        let braces = if labels.is_empty() {
            String::new()
        } else {
            format!("{{{labels}}}")
        };
        let _ = writeln!(out, "{name}_sum{braces} {}", self.sum);
        let _ = writeln!(out, "{name}_count{braces} {}", self.count);
    }
}

/// Counters and histograms shared by the server and the workers.
#[derive(Debug, Default)]
pub struct Metrics {
    pub jobs_submitted: AtomicU64,
    pub jobs_rejected_queue_full: AtomicU64,
    pub jobs_succeeded: AtomicU64,
    pub jobs_cancelled: AtomicU64,
    pub jobs_retried: AtomicU64,
    pub leases_lost: AtomicU64,
    failures: Mutex<BTreeMap<FailureCode, u64>>,
    job_seconds: Mutex<Histogram>,
    stage_seconds: Mutex<BTreeMap<String, Histogram>>,
    http_responses: Mutex<BTreeMap<u16, u64>>,
    http_seconds: Mutex<BTreeMap<String, Histogram>>,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    match m.lock() {
        Ok(g) => g,
        Err(p) => p.into_inner(),
    }
}

/// The `# HELP` and `# TYPE` lines of metric `name`.
fn help(out: &mut String, name: &str, help: &str, kind: &str) {
    let _ = writeln!(out, "# HELP {name} {help}\n# TYPE {name} {kind}");
}

/// Jobs by status, the queue depth and the workers (gauges).
fn render_gauges(out: &mut String, jobs_by_status: &[(String, i64)], workers: usize, busy: usize) {
    let count = |status: &str| {
        jobs_by_status
            .iter()
            .find(|(s, _)| s == status)
            .map_or(0, |(_, n)| *n)
    };
    let _ = writeln!(
        out,
        "# HELP vectorfusion_jobs Jobs in the database by status.\n# TYPE vectorfusion_jobs gauge"
    );
    for st in crate::store::JobStatus::ALL {
        let n = count(st.as_str());
        let _ = writeln!(out, "vectorfusion_jobs{{status=\"{}\"}} {n}", st.as_str());
    }
    let queued = count("queued");
    let _ = writeln!(
        out,
        "# HELP vectorfusion_queue_depth Jobs waiting to run.\n# TYPE vectorfusion_queue_depth gauge\nvectorfusion_queue_depth {queued}"
    );
    let _ = writeln!(
        out,
        "# HELP vectorfusion_workers Worker threads.\n# TYPE vectorfusion_workers gauge\nvectorfusion_workers {workers}\n# HELP vectorfusion_workers_busy Workers running a job.\n# TYPE vectorfusion_workers_busy gauge\nvectorfusion_workers_busy {busy}"
    );
}

fn label_value(s: &str) -> String {
    s.replace('\\', "\\\\")
        .replace('"', "\\\"")
        .replace('\n', "\\n")
}

impl Metrics {
    pub fn inc(counter: &AtomicU64) {
        counter.fetch_add(1, Ordering::Relaxed);
    }

    /// Counts a job that failed for good with `code`.
    pub fn job_failed(&self, code: FailureCode) {
        *lock(&self.failures).entry(code).or_default() += 1;
    }

    pub fn observe_job(&self, seconds: f64) {
        lock(&self.job_seconds).observe(seconds);
    }

    pub fn observe_stage(&self, stage: &str, seconds: f64) {
        lock(&self.stage_seconds)
            .entry(stage.to_string())
            .or_default()
            .observe(seconds);
    }

    pub fn http_response(&self, status: u16) {
        *lock(&self.http_responses).entry(status).or_default() += 1;
    }

    /// Server-side handling time of one request; `route` is a path template like
    /// `POST /jobs/{id}` (keep the label set small).
    pub fn observe_http(&self, route: &str, seconds: f64) {
        lock(&self.http_seconds)
            .entry(route.to_string())
            .or_insert_with(|| Histogram::new(&HTTP_BUCKETS))
            .observe(seconds);
    }

    /// Prometheus text; `jobs_by_status` comes from the database at scrape time.
    pub fn render(&self, jobs_by_status: &[(String, i64)], workers: usize, busy: usize) -> String {
        let mut out = String::new();
        render_gauges(&mut out, jobs_by_status, workers, busy);
        self.render_counters(&mut out);
        self.render_histograms(&mut out);
        out
    }

    /// The job counters, then the failures by code.
    fn render_counters(&self, out: &mut String) {
        let counters: [(&str, &str, &AtomicU64); 6] = [
            (
                "vectorfusion_jobs_submitted_total",
                "Jobs accepted by POST /jobs.",
                &self.jobs_submitted,
            ),
            (
                "vectorfusion_jobs_rejected_total",
                "Submissions refused with 429 because the queue was full.",
                &self.jobs_rejected_queue_full,
            ),
            (
                "vectorfusion_jobs_succeeded_total",
                "Jobs that succeeded.",
                &self.jobs_succeeded,
            ),
            (
                "vectorfusion_jobs_cancelled_total",
                "Jobs cancelled while running.",
                &self.jobs_cancelled,
            ),
            (
                "vectorfusion_jobs_retried_total",
                "Attempts that failed with a retryable error and were re-queued.",
                &self.jobs_retried,
            ),
            (
                "vectorfusion_leases_lost_total",
                "Attempts abandoned because the lease was lost.",
                &self.leases_lost,
            ),
        ];
        for (name, text, c) in counters {
            help(out, name, text, "counter");
            let _ = writeln!(out, "{name} {}", c.load(Ordering::Relaxed));
        }
        help(
            out,
            "vectorfusion_job_failures_total",
            "Jobs that failed for good, by error code.",
            "counter",
        );
        for (code, n) in lock(&self.failures).iter() {
            let _ = writeln!(
                out,
                "vectorfusion_job_failures_total{{code=\"{code}\"}} {n}"
            );
        }
    }

    /// Job and stage durations, then HTTP responses and their handling time.
    fn render_histograms(&self, out: &mut String) {
        let job = "vectorfusion_job_duration_seconds";
        help(out, job, "Wall time of successful attempts.", "histogram");
        lock(&self.job_seconds).render(out, job, "");
        let stage = "vectorfusion_stage_duration_seconds";
        help(out, stage, "Wall time per pipeline stage.", "histogram");
        for (name, h) in lock(&self.stage_seconds).iter() {
            h.render(out, stage, &format!("stage=\"{}\"", label_value(name)));
        }
        let responses = "vectorfusion_http_responses_total";
        help(out, responses, "HTTP responses by status code.", "counter");
        for (code, n) in lock(&self.http_responses).iter() {
            let _ = writeln!(out, "{responses}{{code=\"{code}\"}} {n}");
        }
        let http = "vectorfusion_http_request_duration_seconds";
        let what = "Server-side request handling time (to response headers).";
        help(out, http, what, "histogram");
        for (route, h) in lock(&self.http_seconds).iter() {
            h.render(out, http, &format!("route=\"{}\"", label_value(route)));
        }
    }
}
