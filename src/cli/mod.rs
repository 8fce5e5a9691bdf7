//! The `vectorfusion` command line. Each subcommand lives in its own file; errors are turned
//! into a message and an exit code in one place ([`main`]).

pub mod bench;
pub mod bench_models;
pub mod bench_paint;
pub mod bench_rd;
pub mod bench_stability;
pub mod bench_vectorize;
pub mod eval;
pub mod generate;
pub mod render;
pub mod request_args;
pub mod serve;
pub mod setup;
pub mod tuning;
pub mod vector_args;
pub mod vectorize;

use crate::server::Role;
use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Caption → clean, editable SVG (VectorFusion).
#[derive(Parser, Debug)]
#[command(name = "vectorfusion", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Turn a caption into an SVG.
    Generate(Box<generate::GenerateArgs>),
    /// Trace a raster image into an SVG of closed paths (LIVE).
    Vectorize(vectorize::VectorizeArgs),
    /// Render an SVG through our rasteriser to PNG.
    Render(render::RenderArgs),
    /// Run the HTTP service (API and workers; `--workers 0`: API only).
    Serve(serve::ServeArgs),
    /// Run a worker-only node on a shared (PostgreSQL) queue: health, readiness and metrics.
    Worker(serve::WorkerArgs),
    /// Evaluate generated SVGs with CLIP scorers.
    Eval(Box<eval::EvalArgs>),
    /// Install the embedded model's MiniLM weights into the cache (once; fast when cached).
    Setup(setup::SetupArgs),
    /// Benchmarks.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
    /// Internal: run one job of `serve` in this process (JSON lines on stdin/stdout).
    #[command(hide = true)]
    JobChild,
}

/// Error from a CLI command: a message for the user and an exit code ([`CliError::exit_code`]).
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// A bad flag or flag value (exit code 2).
    #[error("{0}")]
    Usage(String),
    /// Input the command cannot use: a file it cannot read, a directory that is not what the
    /// flag needs (exit code 2). `context` names the input; the cause stays the source.
    #[error("{context}")]
    Input {
        context: String,
        #[source]
        source: anyhow::Error,
    },
    /// A run refused its input: a bad image, SVG or setting (exit code 2).
    #[error(transparent)]
    InvalidRun(crate::pipeline::PipelineError),
    /// The command failed on good input (exit code 1).
    #[error(transparent)]
    Other(#[from] anyhow::Error),
}

impl CliError {
    /// The process exit code: 2 for bad input (flags, values, files), 1 for a failure.
    fn exit_code(&self) -> u8 {
        match self {
            CliError::Usage(_) | CliError::Input { .. } | CliError::InvalidRun(_) => 2,
            CliError::Other(_) => 1,
        }
    }
}

/// Results as bad input or failures of a command, with what was being done as context.
pub(crate) trait ResultExt<T> {
    /// The error as bad input ([`CliError::Input`], exit code 2) about `context`.
    fn bad_input(self, context: impl FnOnce() -> String) -> Result<T, CliError>;
    /// The error as a failure ([`CliError::Other`], exit code 1) while doing `context`.
    fn failed(self, context: impl FnOnce() -> String) -> Result<T, CliError>;
}

impl<T, E: Into<anyhow::Error>> ResultExt<T> for Result<T, E> {
    fn bad_input(self, context: impl FnOnce() -> String) -> Result<T, CliError> {
        self.map_err(|e| CliError::Input {
            context: context(),
            source: e.into(),
        })
    }

    fn failed(self, context: impl FnOnce() -> String) -> Result<T, CliError> {
        self.map_err(|e| CliError::Other(e.into().context(context())))
    }
}

/// The extension of an output path, lower-cased: what format the file is written in.
pub(crate) fn output_extension(path: &std::path::Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
}

/// Writes a result SVG to `path` in the format its extension names: `.pdf` a one-page vector
/// PDF ([`crate::pdf`]), `.png` the resvg render at the SVG's size (as the service's
/// `result.png`), anything else the SVG itself.
pub(crate) fn write_result(path: &std::path::Path, svg: &str) -> Result<(), CliError> {
    let bytes = match output_extension(path).as_deref() {
        Some("pdf") => crate::svg::from_svg(svg)
            .map(|scene| crate::pdf::to_pdf(&scene))
            .failed(|| "converting the result to PDF".into())?,
        Some("png") => crate::svg::render_png(svg, crate::scene::MAX_SIDE as f32)
            .failed(|| "rendering the result to PNG".into())?,
        _ => svg.as_bytes().to_vec(),
    };
    std::fs::write(path, bytes).failed(|| format!("cannot write {}", path.display()))
}

/// A run's error: bad input and missing models are usage errors (exit code 2) said as the
/// stage said them, anything else a failure that keeps the error as its source.
impl From<crate::pipeline::PipelineError> for CliError {
    fn from(e: crate::pipeline::PipelineError) -> Self {
        use crate::pipeline::PipelineError;
        match e {
            PipelineError::InvalidInput(m) => CliError::Usage(m),
            // A stage's error that is the input's fault (a bad image, SVG or setting).
            e if e.code() == crate::pipeline::FailureCode::InvalidInput => CliError::InvalidRun(e),
            // Models missing or failing to load: a setting to fix, the cause kept.
            e if e.code() == crate::pipeline::FailureCode::ModelsNotConfigured => {
                CliError::InvalidRun(e)
            }
            other => CliError::Other(anyhow::Error::new(other)),
        }
    }
}

/// A request the plan refuses: a usage error naming the flag of the refused field.
impl From<crate::pipeline::SpecError> for CliError {
    fn from(e: crate::pipeline::SpecError) -> Self {
        let flag = match e.field {
            "size_conditioning" => "--sdxl-original-size / --sdxl-crop".to_string(),
            f if f.starts_with("size_conditioning.original") => "--sdxl-original-size".into(),
            f if f.starts_with("size_conditioning.crop") => "--sdxl-crop".into(),
            f => format!("--{}", f.replace('_', "-")),
        };
        CliError::Usage(format!("{flag}: {}", e.reason))
    }
}

pub fn run(cli: Cli) -> Result<(), CliError> {
    match cli.command {
        Command::Generate(a) => generate::run(*a),
        Command::Vectorize(a) => vectorize::run(a),
        Command::Render(a) => render::run(a),
        Command::Serve(args) => serve::run(args.node, args.bind, Role::Server),
        Command::Worker(args) => serve::run(args.node, Some(args.bind), Role::Worker),
        Command::Eval(a) => eval::run(*a),
        Command::Setup(a) => setup::run(a),
        Command::Bench(b) => bench::run(b),
        Command::JobChild => match crate::worker::isolate::run_stdio() {
            0 => Ok(()),
            code => Err(CliError::Usage(format!(
                "job-child ended with status {code} (it is started by `serve`, not by hand)"
            ))),
        },
    }
}

/// Parses arguments, runs the command, prints errors and maps them to an exit code.
pub fn main() -> ExitCode {
    crate::alloc::tune();
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", one_line(&e));
            ExitCode::from(e.exit_code())
        }
    }
}

/// The error and its causes on one line, each said once: a message that already quotes its
/// source (`#[error("database error: {0}")]`) is not followed by that source again, as
/// anyhow's `{:#}` would ("database error: refused: refused").
fn one_line(e: &(dyn std::error::Error + 'static)) -> String {
    let mut out = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let text = c.to_string();
        if !out.contains(&text) {
            out.push_str(": ");
            out.push_str(&text);
        }
        cause = c.source();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("connection refused")]
    struct Refused;

    #[derive(Debug, thiserror::Error)]
    enum Quoting {
        #[error("database error: {0}")]
        Db(#[from] Refused),
    }

    #[derive(Debug, thiserror::Error)]
    #[error("opening the store")]
    struct Context(#[source] Quoting);

    #[test]
    fn each_cause_is_said_once() {
        let e = CliError::Other(anyhow::Error::new(Quoting::Db(Refused)));
        assert_eq!(one_line(&e), "database error: connection refused");
        // a cause the message does not quote is appended, then its own source once
        let e = CliError::Other(anyhow::Error::new(Context(Quoting::Db(Refused))));
        assert_eq!(
            one_line(&e),
            "opening the store: database error: connection refused"
        );
        let e = CliError::Other(anyhow::Error::new(Refused).context("reading config.toml"));
        assert_eq!(one_line(&e), "reading config.toml: connection refused");
        assert_eq!(one_line(&CliError::Usage("bad".into())), "bad");
    }
}
