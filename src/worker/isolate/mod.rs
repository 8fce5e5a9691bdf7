//! Jobs in their own processes: [`ProcessExecutor`] runs each job in a child process of this
//! binary (`vectorfusion job-child`, [`child`]), so a job that exhausts memory, crashes or hangs
//! ends as a failed job (`resource_limit`, `crashed`) while the server and the other jobs go on.
//!
//! The parent watches the child: its resident memory (Linux `/proc/<pid>/status`, read every
//! [`POLL`]) against [`JobLimits::max_rss_bytes`], and its running time against
//! [`JobLimits::max_wall`]; past either, the child is killed. Progress, snapshots and
//! checkpoints come back as JSON lines ([`protocol`]) and go to the worker's [`JobContext`]
//! unchanged, so resume, cancellation and SSE work as in-process. A checkpoint the store
//! refuses (the lease is gone) kills the child. If the server dies, the child reads end-of-file
//! on stdin and exits.
//!
//! Planning and `text_ready` stay in the server (the `inner` executor); only `run` crosses.

mod child;
pub mod protocol;

pub use child::run_stdio;
pub use protocol::ChildExecutor;

use crate::pipeline::{
    Executor, JobContext, JobSpec, Limits, PipelineError, PlanRequest, RunOutput, RunPlan,
    SpecError,
};
use protocol::{CANCEL, FromChild, write_start};
use std::io::{BufRead, BufReader, Write};
use std::path::PathBuf;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, RecvTimeoutError, channel};
use std::time::{Duration, Instant};

/// How often the parent checks the child's memory, time and cancellation.
pub const POLL: Duration = Duration::from_millis(50);

/// Limits of one job process. Zero means no limit.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JobLimits {
    /// Resident memory of the job process, in bytes (checked every [`POLL`]: a job can pass it
    /// by what it allocates in that time before it is killed).
    pub max_rss_bytes: u64,
    /// Running time of the job process.
    pub max_wall: Duration,
}

/// Runs each job in a child process (see the module docs).
pub struct ProcessExecutor {
    exe: PathBuf,
    child: ChildExecutor,
    inner: Arc<dyn Executor>,
    limits: JobLimits,
}

impl ProcessExecutor {
    /// `exe` is this program (`std::env::current_exe()`; tests name the built binary); the
    /// child builds `child`; `inner` answers planning and readiness in the server and must
    /// match `child`.
    pub fn new(
        exe: PathBuf,
        child: ChildExecutor,
        inner: Arc<dyn Executor>,
        limits: JobLimits,
    ) -> Self {
        ProcessExecutor {
            exe,
            child,
            inner,
            limits,
        }
    }
}

/// Kills and reaps the child when dropped (a panic or an early return never leaves it behind).
struct Reaped(Child);

impl Drop for Reaped {
    fn drop(&mut self) {
        if matches!(self.0.try_wait(), Ok(None)) {
            let _ = self.0.kill();
        }
        let _ = self.0.wait();
    }
}

impl Executor for ProcessExecutor {
    fn run(&self, spec: &JobSpec, ctx: &JobContext) -> Result<RunOutput, PipelineError> {
        let mut child = self.spawn()?;
        let mut stdin = child.0.stdin.take();
        // A child that dies at once closes its stdin; the outcome below says why.
        if let Some(w) = stdin.as_mut() {
            let resume = ctx.resume_state();
            let every = ctx.checkpoint_every();
            let _ = write_start(w, self.child.clone(), spec, resume, every);
        }
        let (rx, reader) = read_lines(&mut child)?;
        let mut watch = Watch {
            limits: self.limits,
            pid: child.0.id(),
            began: Instant::now(),
            outcome: None,
            stopped: None,
            cancel_sent: false,
        };
        watch.watch(&mut child, stdin.as_mut(), &rx, ctx);
        drop(stdin);
        let status = child.0.wait();
        let _ = reader.join();
        if let Some(e) = watch.stopped {
            return Err(e);
        }
        watch.outcome.unwrap_or_else(|| {
            let how = match status {
                Ok(s) => describe(s),
                Err(e) => format!("its status is unknown ({e})"),
            };
            Err(PipelineError::Crashed(format!(
                "it ended without a result: {how}"
            )))
        })
    }

    fn text_ready(&self) -> Result<(), crate::pipeline::NotReady> {
        self.inner.text_ready()
    }

    fn plan(&self, request: &PlanRequest, limits: &Limits) -> Result<RunPlan, SpecError> {
        self.inner.plan(request, limits)
    }
}

impl ProcessExecutor {
    /// Starts the job process (`vectorfusion job-child`) with piped stdin and stdout.
    fn spawn(&self) -> Result<Reaped, PipelineError> {
        Command::new(&self.exe)
            .arg("job-child")
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map(Reaped)
            .map_err(|e| PipelineError::Transient(format!("cannot start the job process: {e}")))
    }
}

/// The lines the job process writes, from a reader thread (it ends with the process's stdout).
fn read_lines(
    child: &mut Reaped,
) -> Result<(Receiver<String>, std::thread::JoinHandle<()>), PipelineError> {
    let stdout = child
        .0
        .stdout
        .take()
        .ok_or_else(|| PipelineError::Transient("the job process has no stdout".into()))?;
    let (tx, rx) = channel::<String>();
    let reader = std::thread::Builder::new()
        .name("vf-job-out".into())
        .spawn(move || {
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        })
        .map_err(|e| PipelineError::Transient(format!("cannot start a reader thread: {e}")))?;
    Ok((rx, reader))
}

/// A running job process as the parent watches it.
struct Watch {
    limits: JobLimits,
    pid: u32,
    began: Instant,
    /// What the job process answered (`done` or `error`).
    outcome: Option<Result<RunOutput, PipelineError>>,
    /// Why the parent killed it (a limit, a refused checkpoint).
    stopped: Option<PipelineError>,
    cancel_sent: bool,
}

impl Watch {
    /// Relays the job process's lines to `ctx` until its stdout closes; every [`POLL`] passes
    /// a cancellation on and checks the limits.
    fn watch(
        &mut self,
        child: &mut Reaped,
        mut stdin: Option<&mut ChildStdin>,
        rx: &Receiver<String>,
        ctx: &JobContext,
    ) {
        let mut last_check = self.began;
        loop {
            match rx.recv_timeout(POLL) {
                Ok(line) => self.on_line(child, &line, ctx),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
            if self.stopped.is_some() || last_check.elapsed() < POLL {
                continue;
            }
            last_check = Instant::now();
            if ctx.is_cancelled() && !self.cancel_sent {
                self.cancel_sent = true;
                if let Some(w) = stdin.as_mut() {
                    let _ = writeln!(w, "{CANCEL}").and_then(|()| w.flush());
                }
            }
            if let Some(e) = self.over_limit() {
                let _ = child.0.kill();
                self.stopped = Some(e);
            }
        }
    }

    /// One line of the job process: progress and checkpoints go to `ctx`, `done` and `error`
    /// are the outcome, anything else is its log.
    fn on_line(&mut self, child: &mut Reaped, line: &str, ctx: &JobContext) {
        match serde_json::from_str::<FromChild>(line) {
            Ok(FromChild::Progress(p)) => ctx.report(p),
            Ok(FromChild::Checkpoint(v)) => {
                if let Err(e) = ctx.checkpoint(v) {
                    let _ = child.0.kill();
                    self.stopped.get_or_insert(e.into());
                }
            }
            Ok(FromChild::Done(out)) => self.outcome = Some(Ok(*out)),
            Ok(FromChild::Error { code, message }) => {
                self.outcome = Some(Err(PipelineError::reported(code, message)))
            }
            Err(_) => tracing::info!(target: "job_child", "{line}"),
        }
    }

    /// The limit the job process has passed, if any.
    fn over_limit(&self) -> Option<PipelineError> {
        let limit = self.limits;
        if !limit.max_wall.is_zero() && self.began.elapsed() > limit.max_wall {
            return Some(PipelineError::ResourceLimit(format!(
                "the job ran longer than its wall-clock limit of {} s (queue.job_wall_secs)",
                limit.max_wall.as_secs()
            )));
        }
        if limit.max_rss_bytes == 0 {
            return None;
        }
        let rss = rss_bytes(self.pid)?;
        (rss > limit.max_rss_bytes).then(|| {
            PipelineError::ResourceLimit(format!(
                "the job used {} MiB of memory, past its limit of {} MiB (queue.job_memory_mb)",
                rss >> 20,
                limit.max_rss_bytes >> 20
            ))
        })
    }
}

/// "killed by signal 9" / "exit status 3".
fn describe(status: std::process::ExitStatus) -> String {
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        if let Some(sig) = status.signal() {
            return format!("killed by signal {sig}");
        }
    }
    format!("{status}")
}

/// Resident memory of process `pid` in bytes (Linux); `None` elsewhere or once it is gone.
fn rss_bytes(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}
