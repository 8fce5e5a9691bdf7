//! The request flags `generate`, `eval` and `bench stability` share, as flag groups each
//! command flattens: the teacher ([`ModelArgs`]), the budget ([`BudgetArgs`]) and the rest of
//! a text request ([`RequestArgs`], turned into the plan's [`PlanRequest`] by
//! [`RequestArgs::plan_request`]), and the limits every command-line plan is checked against
//! ([`cli_limits`]). Values are parsed by clap, so a bad one is a usage error (exit code 2)
//! naming its flag.

use super::tuning::SdsTuningArgs;
use crate::models::ComputeDevice;
use crate::pipeline::{Limits, Method, ModelDirs, PlanRequest, Preset, Style};
use std::path::PathBuf;
use std::str::FromStr;

/// The teacher of a run: a Stable Diffusion directory or the analytic TEST teacher, and the
/// device the model runs on.
#[derive(clap::Args, Debug, Clone)]
pub struct ModelArgs {
    /// Stable Diffusion model directory (diffusers layout).
    #[arg(long, conflicts_with = "teacher")]
    pub model: Option<PathBuf>,
    /// `analytic:DIR`: the analytic TEST teacher built from the PNG targets in DIR (held as
    /// DIR).
    #[arg(long, value_name = "analytic:DIR", value_parser = parse_analytic_teacher)]
    pub teacher: Option<PathBuf>,
    /// Where the diffusion model runs: cpu, cuda or cuda:N (CUDA needs a build with the `cuda`
    /// feature).
    #[arg(long, default_value = "cpu", value_parser = parse_device)]
    pub device: ComputeDevice,
}

impl ModelArgs {
    /// The model directories these flags name, with `scorer` for reranking (no TAESD, the
    /// default encoder; no default model).
    pub fn model_dirs(&self, scorer: Option<PathBuf>) -> ModelDirs {
        ModelDirs {
            sd_dir: self.model.clone(),
            clip_dir: scorer,
            device: self.device,
            analytic_dir: self.teacher.clone(),
            ..ModelDirs::default()
        }
    }
}

/// The work of a text run: SDS steps, paths and samples, each the preset's when omitted.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct BudgetArgs {
    /// SDS steps [default: the preset's].
    #[arg(long)]
    pub steps: Option<u32>,
    /// Number of paths or strokes (pixel art is always a 32x32 grid) [default: the preset's].
    #[arg(long)]
    pub paths: Option<u32>,
    /// Images sampled for sd_live / sd_live_sds (K) [default: the preset's].
    #[arg(long)]
    pub samples: Option<u32>,
}

/// A text request's flags besides the caption and the method: style, preset, budget, seed,
/// retrieval and the SDS tuning.
#[derive(clap::Args, Debug, Clone)]
pub struct RequestArgs {
    /// Style: iconography, pixel_art, sketch, low_poly or painting (`pixel-art`, `low-poly`,
    /// `icon`, `line` are accepted too).
    #[arg(long, default_value = "iconography", value_parser = parse_word::<Style>)]
    pub style: Style,
    /// Preset: draft, fast, balanced, paper or cpu (resolution, steps, paths, samples, sampler
    /// steps, LIVE iterations; cpu: Stable Diffusion in ≤ 10 minutes on 2 cores; `default` and
    /// `quality` are older names of balanced and paper).
    #[arg(long, default_value = "balanced", value_parser = parse_word::<Preset>)]
    pub preset: Preset,
    #[command(flatten)]
    pub budget: BudgetArgs,
    /// Seed of the run.
    #[arg(long, default_value_t = 0, value_parser = crate::pipeline::parse_seed)]
    pub seed: u64,
    /// Sample from noise only: no retrieved training icons as starting points (the embedded
    /// model starts a share of its K samples, `_retrieval_share`, from the icons nearest to the
    /// caption).
    #[arg(long)]
    pub no_retrieval: bool,
    /// The SDS stage's settings.
    #[command(flatten)]
    pub tuning: SdsTuningArgs,
}

impl RequestArgs {
    /// The text request these flags make for `caption` by `method`, started from the method
    /// (no image or SVG), default vector options and no snapshots.
    pub fn plan_request(&self, caption: &str, method: Method) -> PlanRequest {
        PlanRequest {
            style: self.style,
            method,
            preset: self.preset,
            paths: self.budget.paths,
            steps: self.budget.steps,
            samples: self.budget.samples,
            seed: self.seed,
            retrieval: !self.no_retrieval,
            tuning: self.tuning.tuning(None),
            ..PlanRequest::text(caption)
        }
    }
}

/// A `--teacher` that is not `analytic:DIR`.
#[derive(Debug, thiserror::Error)]
#[error("unknown teacher {0:?}: the only test teacher is analytic:DIR")]
pub struct UnknownTeacher(pub String);

/// Limits of a command-line run: only what the stages themselves cap.
pub fn cli_limits() -> Limits {
    Limits {
        max_paths: crate::scene::MAX_PATHS as u32,
        max_steps: u32::MAX,
        max_samples: u32::MAX,
        ..Limits::default()
    }
}

/// `--teacher analytic:DIR`: DIR (the only test teacher).
pub fn parse_analytic_teacher(spec: &str) -> Result<PathBuf, UnknownTeacher> {
    spec.strip_prefix("analytic:")
        .map(PathBuf::from)
        .ok_or_else(|| UnknownTeacher(spec.to_string()))
}

/// `--device`: cpu, cuda or cuda:N, refused up front when this build cannot open it.
pub fn parse_device(s: &str) -> Result<ComputeDevice, crate::models::DeviceError> {
    ComputeDevice::parse_built(s)
}

/// A vocabulary word (`--method`, `--style`, `--preset`) as its type's [`FromStr`] reads it:
/// any case, `-` for `_`, with the type's older names and aliases.
pub fn parse_word<T: FromStr>(s: &str) -> Result<T, T::Err> {
    s.parse()
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        request: RequestArgs,
        #[command(flatten)]
        model: ModelArgs,
    }

    fn parse(args: &[&str]) -> Result<Cli, clap::Error> {
        Cli::try_parse_from(std::iter::once("x").chain(args.iter().copied()))
    }

    #[test]
    fn defaults_and_spellings() {
        let c = parse(&[]).unwrap();
        assert_eq!(
            (c.request.style, c.request.preset),
            (Style::Iconography, Preset::Balanced)
        );
        assert_eq!(c.model.device, ComputeDevice::Cpu);
        let c = parse(&["--style", "Pixel-Art", "--preset", "QUALITY"]).unwrap();
        assert_eq!(
            (c.request.style, c.request.preset),
            (Style::PixelArt, Preset::Paper)
        );
        let c = parse(&["--teacher", "analytic:/t"]).unwrap();
        assert_eq!(c.model.teacher, Some(PathBuf::from("/t")));
    }

    #[test]
    fn bad_values_are_usage_errors() {
        for bad in [
            &["--style", "oil"][..],
            &["--preset", "best"],
            &["--teacher", "magic:x"],
            &["--device", "tpu"],
            &["--model", "m", "--teacher", "analytic:t"],
        ] {
            let e = parse(bad).err().unwrap();
            assert_eq!(e.exit_code(), 2, "{bad:?}");
        }
    }

    #[test]
    fn the_request_carries_every_flag() {
        let c = parse(&[
            "--steps",
            "7",
            "--paths",
            "9",
            "--samples",
            "2",
            "--seed",
            "5",
            "--no-retrieval",
            "--t-min",
            "100",
        ])
        .unwrap();
        let r = c.request.plan_request("a cat", Method::SdLive);
        assert_eq!((r.steps, r.paths, r.samples), (Some(7), Some(9), Some(2)));
        assert_eq!((r.seed, r.retrieval, r.method), (5, false, Method::SdLive));
        assert_eq!(r.tuning.t_min, Some(100));
        assert_eq!(r.caption.as_deref(), Some("a cat"));
    }
}
