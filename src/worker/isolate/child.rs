//! The job process (`vectorfusion job-child`, started by [`super::ProcessExecutor`]): reads a
//! [`Start`] from stdin, runs the job with the executor it names, and writes progress,
//! checkpoints and the outcome to stdout. Logs go to stderr. When stdin closes (the server is
//! gone) it exits at once.

use super::protocol::{CANCEL, ChildExecutor, FromChild, read_start};
use crate::pipeline::{DefaultExecutor, Executor, JobContext, PipelineError};
use crate::progress::{CancelToken, CheckpointError};
use crate::worker::test_executor::TestExecutor;
use std::io::{BufRead, Write};
use std::panic::AssertUnwindSafe;
use std::sync::{Arc, Mutex};

/// Exit status when the server went away before the job ended.
const ORPHANED: i32 = 70;

/// Runs one job over stdin/stdout; returns the process exit status (0 once an outcome was
/// written, 2 for an unreadable start).
pub fn run_stdio() -> i32 {
    let start = match read_start(&mut std::io::stdin().lock()) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("job-child: {e}");
            return 2;
        }
    };
    let out = Arc::new(Mutex::new(std::io::stdout()));
    let send = {
        let out = out.clone();
        move |msg: &FromChild| -> std::io::Result<()> {
            let mut line = serde_json::to_vec(msg).map_err(std::io::Error::other)?;
            line.push(b'\n');
            let mut o = out
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            o.write_all(&line).and_then(|()| o.flush())
        }
    };
    let cancel = CancelToken::new();
    let watch = cancel.clone();
    std::thread::spawn(move || {
        for line in std::io::stdin().lock().lines() {
            match line {
                Ok(l) if l.trim() == CANCEL => watch.cancel(),
                Ok(_) => {}
                Err(_) => break,
            }
        }
        std::process::exit(ORPHANED);
    });
    let executor: Box<dyn Executor> = match start.executor {
        ChildExecutor::Pipeline { models } => Box::new(DefaultExecutor::new(models)),
        ChildExecutor::Test { step_ms } => Box::new(TestExecutor::new(step_ms)),
    };
    let progress = {
        let send = send.clone();
        move |p| {
            let _ = send(&FromChild::Progress(p));
        }
    };
    let checkpoint = {
        let send = send.clone();
        move |v| send(&FromChild::Checkpoint(v)).map_err(|e| CheckpointError::Store(Box::new(e)))
    };
    let ctx = JobContext::new(
        Arc::new(progress),
        cancel,
        start.checkpoint_every,
        Box::new(checkpoint),
        start.resume,
    );
    let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| executor.run(&start.spec, &ctx)))
        .unwrap_or_else(|panic| Err(PipelineError::panicked(panic.as_ref())));
    let msg = match outcome {
        Ok(out) => FromChild::Done(Box::new(out)),
        Err(e) => FromChild::Error {
            code: e.code(),
            message: e.to_string(),
        },
    };
    match send(&msg) {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("job-child: the server stopped reading: {e}");
            ORPHANED
        }
    }
}
