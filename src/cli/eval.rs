//! `vectorfusion eval`: CLIP R-Precision and CLIP similarity of generated SVGs (Table 1).
//!
//! `--svgs DIR` scores SVGs generated elsewhere; `--method M` (repeatable) first generates one
//! SVG per caption with the shared pipeline ([`DefaultExecutor`], exactly what `generate` and
//! the service run), writing `OUT_DIR/M/0001.svg`… (and each run's report, `0001.json`), then
//! scores that directory the same way and adds the mean generation seconds per SVG; captions
//! that name a colour also get its colour binding ([`crate::eval::colour`]). `--method samples` scores the prior's raster
//! samples themselves (K per caption, the rerank scorer's pick kept, saved as `NNNN.png`): the
//! raster row of the paper's Table 1, the ceiling the vector methods are measured against.

use super::request_args::{ModelArgs, RequestArgs};
use super::{CliError, ResultExt};
use crate::eval::clip::{
    EvalError, EvalReport, evaluate, evaluate_svg_dir, format_table, read_prompts, svg_name,
};
use crate::models::scorer::Scorer;
use crate::pipeline::{
    DefaultExecutor, Executor, JobContext, Limits, Method, PlanRequest, Preset, RunInput, RunPlan,
    Style,
};
use crate::progress::{CancelToken, NullSink};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Evaluate SVGs generated from a caption file with one or more CLIP scorers.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// Caption file, one caption per line (line N ↔ NNNN.svg).
    #[arg(long)]
    pub prompts: PathBuf,
    /// Generate with this method (scratch, sd_live, sd_live_sds, or `samples` for the raster
    /// samples of the diffusion model before any vectorisation), then evaluate; repeat for
    /// several methods (one table row each).
    #[arg(
        long = "method",
        conflicts_with = "svgs",
        required_unless_present = "svgs",
        value_parser = EvalMethod::parse
    )]
    pub methods: Vec<EvalMethod>,
    /// Evaluate already generated SVGs `0001.svg`, `0002.svg`, ... in this directory.
    #[arg(long)]
    pub svgs: Option<PathBuf>,
    /// CLIP model directory (transformers or OpenCLIP layout), hub repo id (`org/name`,
    /// from the HF cache, downloaded when online), or an IconClip model directory such as
    /// `models/vf-icon` (its `scorer/`); repeat for several scorers.
    #[arg(long = "scorer", required = true)]
    pub scorers: Vec<String>,
    /// `--json`: print JSON instead of the table; `--json OUT`: write the JSON report to OUT
    /// (and print the table).
    #[arg(long, num_args = 0..=1, value_name = "OUT")]
    pub json: Option<Option<PathBuf>>,
    /// Also write the JSON report to this file.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Only the first N captions.
    #[arg(long)]
    pub limit: Option<usize>,
    /// --method: where the SVGs go (OUT_DIR/METHOD/0001.svg, ...).
    #[arg(long, default_value = "eval-out")]
    pub out_dir: PathBuf,
    /// --method: the teacher (without --model or --teacher, the embedded default model).
    #[command(flatten)]
    pub model: ModelArgs,
    /// --method: CLIP directory used to keep the best of the K samples (sd_live*); without it
    /// the first sample is kept. (Not one of the evaluation scorers, to keep the metric fair.)
    #[arg(long)]
    pub rerank_scorer: Option<PathBuf>,
    /// --method: the request (style, preset, budget, seed, SDS settings); the seed of caption
    /// line N is SEED + N - 1.
    #[command(flatten)]
    pub request: RequestArgs,
}

fn map_err(e: EvalError) -> CliError {
    match e {
        EvalError::Clip(c) => CliError::Other(anyhow::Error::new(c)),
        EvalError::Scorer(c) => CliError::Other(anyhow::Error::new(c)),
        other => CliError::Usage(other.to_string()),
    }
}

/// `--method` output: one report per method.
#[derive(Debug, Serialize)]
pub struct MethodsReport {
    pub prompts: usize,
    pub style: Style,
    pub preset: Preset,
    pub methods: Vec<EvalReport>,
}

pub fn run(args: EvalArgs) -> Result<(), CliError> {
    let mut captions = read_prompts(&args.prompts).map_err(map_err)?;
    if let Some(n) = args.limit {
        if n == 0 {
            return Err(CliError::Usage("--limit must be positive".into()));
        }
        captions.truncate(n);
    }
    let mut scorers = Vec::with_capacity(args.scorers.len());
    for s in &args.scorers {
        let sc = Scorer::load_source(s, true).map_err(|e| CliError::Other(e.into()))?;
        scorers.push(sc);
    }
    let (json, table) = match &args.svgs {
        Some(dir) => {
            let report = evaluate_svg_dir(&captions, dir, &scorers).map_err(map_err)?;
            (to_json(&report)?, format_table(&report))
        }
        None => {
            let report = generate_and_evaluate(&args, &captions, &scorers)?;
            (to_json(&report)?, format_methods_table(&report))
        }
    };
    let json_file = args.json.as_ref().and_then(Option::as_ref);
    for out in args.out.iter().chain(json_file) {
        write(out, &json)?;
    }
    if matches!(args.json, Some(None)) {
        println!("{json}");
    } else {
        print!("{table}");
    }
    Ok(())
}

fn to_json<T: Serialize>(v: &T) -> Result<String, CliError> {
    serde_json::to_string_pretty(v).failed(|| "encoding the report".into())
}

/// Generates `dir/0001.svg`… for every method with the shared pipeline, then scores each
/// directory like `--svgs`.
fn generate_and_evaluate(
    args: &EvalArgs,
    captions: &[String],
    scorers: &[Scorer],
) -> Result<MethodsReport, CliError> {
    let exec = executor(args)?;
    let mut reports = Vec::with_capacity(args.methods.len());
    for method in &args.methods {
        let dir = args.out_dir.join(method.as_str());
        std::fs::create_dir_all(&dir).failed(|| dir.display().to_string())?;
        let run = MethodRun {
            args,
            exec: &exec,
            captions,
            scorers,
            dir: &dir,
        };
        reports.push(match *method {
            EvalMethod::Samples => run.samples()?,
            EvalMethod::Pipeline(m) => run.pipeline(m)?,
        });
    }
    Ok(MethodsReport {
        prompts: captions.len(),
        style: args.request.style,
        preset: args.request.preset,
        methods: reports,
    })
}

/// The executor of `--method`: `--model`, `--teacher`, else the embedded default model (and
/// its scorer for reranking), checked ready for text runs.
fn executor(args: &EvalArgs) -> Result<DefaultExecutor, CliError> {
    let default_model =
        crate::pipeline::default_model_dir().map_err(|e| CliError::Usage(e.to_string()))?;
    let dirs = args
        .model
        .model_dirs(args.rerank_scorer.clone())
        .or_default_model(default_model);
    if dirs.sd_dir.is_none() && dirs.analytic_dir.is_none() {
        return Err(CliError::Usage(
            "--method generates SVGs: give --model DIR (Stable Diffusion) or --teacher analytic:DIR \
             (the embedded default model was not found)"
                .into(),
        ));
    }
    let exec = DefaultExecutor::new(dirs);
    exec.text_ready()
        .map_err(|e| CliError::Usage(e.to_string()))?;
    Ok(exec)
}

/// One method's row of `--method`: every caption generated into `dir`, then scored.
struct MethodRun<'a> {
    args: &'a EvalArgs,
    exec: &'a DefaultExecutor,
    captions: &'a [String],
    scorers: &'a [Scorer],
    dir: &'a Path,
}

impl MethodRun<'_> {
    /// `dir/NNNN.svg` for every caption by `method`, scored like `--svgs`, with the mean
    /// generation seconds.
    fn pipeline(&self, method: Method) -> Result<EvalReport, CliError> {
        let name = method.as_str();
        let mut seconds = 0.0;
        for (i, caption) in self.captions.iter().enumerate() {
            let line = i + 1;
            let plan = self.plan(method, caption, line)?;
            let t0 = std::time::Instant::now();
            let input = RunInput {
                caption: Some(caption.clone()),
                ..RunInput::default()
            };
            let out =
                self.exec
                    .run_plan(&plan, &input, &JobContext::detached(CancelToken::new()))?;
            // The pipeline's own time (model loading excluded); wall time as a fallback.
            let secs = out
                .report
                .seconds
                .unwrap_or_else(|| t0.elapsed().as_secs_f64());
            seconds += secs;
            let path = self.dir.join(svg_name(line));
            write(&path, &out.svg)?;
            // The run's report beside it (what retrieval, rerank and steering did).
            write(&path.with_extension("json"), &to_json(&out.report)?)?;
            let n = self.captions.len();
            eprintln!(
                "{name} {line}/{n}: {} paths, {secs:.1} s -> {}",
                out.paths,
                path.display()
            );
        }
        let mut report =
            evaluate_svg_dir(self.captions, self.dir, self.scorers).map_err(map_err)?;
        report.method = name.to_string();
        report.mean_seconds = Some(seconds / self.captions.len().max(1) as f64);
        Ok(report)
    }

    /// `--method samples`: K raster samples per caption from the same model and preset as
    /// `sd_live*`, the rerank scorer's pick kept (`dir/NNNN.png`) and scored as an image.
    fn samples(&self) -> Result<EvalReport, CliError> {
        let cancel = CancelToken::new();
        let mut images = Vec::with_capacity(self.captions.len());
        let mut seconds = 0.0;
        for (i, caption) in self.captions.iter().enumerate() {
            let line = i + 1;
            let plan = self
                .plan(Method::SdLive, caption, line)?
                .text
                .ok_or_else(|| CliError::Usage("samples need a text model".into()))?;
            let k = plan.sample.as_ref().map_or(1, |s| s.samples);
            let models = self.exec.load_models(&plan)?;
            let t0 = std::time::Instant::now();
            let (ranked, _) =
                crate::pipeline::sample_ranked(&models, &plan, caption, &NullSink, &cancel)?;
            let secs = t0.elapsed().as_secs_f64();
            seconds += secs;
            let path = self.dir.join(format!("{line:04}.png"));
            let best = ranked.best_image();
            best.save_png(&path).failed(|| path.display().to_string())?;
            let n = self.captions.len();
            eprintln!(
                "samples {line}/{n}: best of {k}, {secs:.1} s -> {}",
                path.display()
            );
            images.push(best.clone());
        }
        let mut results = Vec::with_capacity(self.scorers.len());
        for s in self.scorers {
            results.push(evaluate(s, self.captions, &images).map_err(map_err)?);
        }
        Ok(EvalReport {
            method: "samples".into(),
            prompts: self.captions.len(),
            mean_paths: 0.0,
            mean_seconds: Some(seconds / self.captions.len().max(1) as f64),
            scorers: results,
            colour_binding: crate::eval::colour::colour_binding(self.captions, &images),
        })
    }

    /// The plan of caption `line` by `method`; a refused request names its line.
    fn plan(&self, method: Method, caption: &str, line: usize) -> Result<RunPlan, CliError> {
        self.exec
            .plan(
                &request(self.args, method, caption, line),
                &Limits::default(),
            )
            .map_err(|e| CliError::Usage(format!("line {line}: {e}")))
    }
}

/// A row of the evaluation table: a pipeline method, or the raster samples it starts from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EvalMethod {
    /// SVGs generated by this method.
    Pipeline(Method),
    /// The prior's raster samples (the rerank scorer's pick of K per caption).
    Samples,
}

/// A `--method` that is neither a pipeline method nor `samples`.
#[derive(Debug, thiserror::Error)]
#[error("{0} (or `samples`)")]
pub struct UnknownEvalMethod(String);

impl EvalMethod {
    /// `samples` (any case), else a pipeline method.
    pub fn parse(s: &str) -> Result<Self, UnknownEvalMethod> {
        if s.eq_ignore_ascii_case("samples") {
            return Ok(Self::Samples);
        }
        s.parse::<Method>()
            .map(Self::Pipeline)
            .map_err(|e| UnknownEvalMethod(e.to_string()))
    }

    fn as_str(self) -> &'static str {
        match self {
            Self::Pipeline(m) => m.as_str(),
            Self::Samples => "samples",
        }
    }
}

/// The request `eval --method` makes for caption `line` (seeds advance by line).
fn request(args: &EvalArgs, method: Method, caption: &str, line: usize) -> PlanRequest {
    let r = args.request.plan_request(caption, method);
    PlanRequest {
        seed: r.seed.wrapping_add(line as u64 - 1),
        ..r
    }
}

fn write(path: &Path, text: &str) -> Result<(), CliError> {
    std::fs::write(path, text).failed(|| path.display().to_string())
}

/// Table 1: one row per method (paths and seconds per SVG, then R-Precision and similarity per
/// scorer).
pub fn format_methods_table(r: &MethodsReport) -> String {
    let mut s = format!("{} prompts\n", r.prompts);
    let w = r
        .methods
        .iter()
        .map(|m| m.method.chars().count())
        .max()
        .unwrap_or(6)
        .max(6);
    s.push_str(&format!(
        "{:<w$}  {:>9}  {:>7}",
        "method", "paths/SVG", "s/SVG"
    ));
    let names: Vec<&str> = r
        .methods
        .first()
        .map(|m| m.scorers.iter().map(|x| x.scorer.as_str()).collect())
        .unwrap_or_default();
    for n in &names {
        s.push_str(&format!(
            "  {:>14}  {:>10}",
            format!("R-Prec {n}"),
            "CLIP sim"
        ));
    }
    s.push('\n');
    for m in &r.methods {
        let secs = m.mean_seconds.map_or("n/a".into(), |v| format!("{v:.1}"));
        s.push_str(&format!(
            "{:<w$}  {:>9.1}  {:>7}",
            m.method, m.mean_paths, secs
        ));
        for x in &m.scorers {
            s.push_str(&format!(
                "  {:>13.1}%  {:>10.2}",
                100.0 * x.r_precision,
                x.mean_similarity
            ));
        }
        if let Some(c) = &m.colour_binding {
            s.push_str(&format!("  colour {c}"));
        }
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        eval: EvalArgs,
    }

    fn args(extra: &[&str]) -> EvalArgs {
        let base = [
            "eval",
            "--prompts",
            "p.txt",
            "--scorer",
            "s",
            "--method",
            "sd_live_sds",
        ];
        Cli::try_parse_from(base.iter().chain(extra)).unwrap().eval
    }

    /// The SDS flags (a sweep's knobs) reach every caption's request; without them the preset
    /// and the model decide.
    #[test]
    fn sds_flags_reach_the_request() {
        let a = args(&[
            "--guidance",
            "30",
            "--t-min",
            "200",
            "--t-max",
            "800",
            "--size",
            "96",
            "--no-augment",
        ]);
        let r = request(&a, Method::SdLiveSds, "a cat", 3);
        assert_eq!(r.tuning.guidance, Some(30.0));
        assert_eq!((r.tuning.t_min, r.tuning.t_max), (Some(200), Some(800)));
        assert_eq!(r.tuning.size, Some(96));
        assert_eq!(r.tuning.augment, Some(false));
        assert_eq!(r.seed, 2, "line 3 of seed 0");
        let plain = request(&args(&[]), Method::SdLiveSds, "a cat", 1);
        assert_eq!(plain.tuning, Default::default());
        assert!(
            Cli::try_parse_from([
                "eval",
                "--prompts",
                "p",
                "--scorer",
                "s",
                "--method",
                "samples",
                "--t-min",
                "x"
            ])
            .is_err()
        );
    }
}
