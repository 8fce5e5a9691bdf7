//! `vectorfusion eval`: CLIP R-Precision and CLIP similarity of generated SVGs (Table 1).

use super::CliError;
use crate::eval::clip::{EvalError, evaluate_svg_dir, format_table, read_prompts};
use crate::models::scorer::Scorer;
use std::path::PathBuf;

/// Evaluate SVGs generated from a caption file with one or more CLIP scorers.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// Caption file, one caption per line (line N ↔ NNNN.svg).
    #[arg(long)]
    pub prompts: PathBuf,
    /// Generate with this method, then evaluate.
    #[arg(long, conflicts_with = "svgs", required_unless_present = "svgs")]
    pub method: Option<String>,
    /// Evaluate already generated SVGs `0001.svg`, `0002.svg`, ... in this directory.
    #[arg(long)]
    pub svgs: Option<PathBuf>,
    /// CLIP model directory (transformers or OpenCLIP layout), hub repo id (`org/name`,
    /// from the HF cache, downloaded when online), or an IconClip model directory such as
    /// `models/vf-icon` (its `scorer/`); repeat for several scorers.
    #[arg(long = "scorer", required = true)]
    pub scorers: Vec<String>,
    /// Print JSON instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Also write the JSON report to this file.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

fn map_err(e: EvalError) -> CliError {
    match e {
        EvalError::Clip(c) => CliError::Other(anyhow::Error::new(c)),
        EvalError::Scorer(c) => CliError::Other(anyhow::Error::new(c)),
        other => CliError::Usage(other.to_string()),
    }
}

pub fn run(args: EvalArgs) -> Result<(), CliError> {
    let captions = read_prompts(&args.prompts).map_err(map_err)?;
    let Some(dir) = args.svgs else {
        return Err(CliError::NotImplemented(
            "eval --method (generation is not wired into eval yet; generate SVGs and pass --svgs DIR)",
        ));
    };
    let mut scorers = Vec::with_capacity(args.scorers.len());
    for s in &args.scorers {
        let sc = Scorer::load_source(s, true).map_err(|e| CliError::Other(e.into()))?;
        scorers.push(sc);
    }
    let report = evaluate_svg_dir(&captions, &dir, &scorers).map_err(map_err)?;
    let json = serde_json::to_string_pretty(&report).map_err(|e| CliError::Other(e.into()))?;
    if let Some(out) = &args.out {
        std::fs::write(out, &json)
            .map_err(|e| CliError::Other(anyhow::anyhow!("{}: {e}", out.display())))?;
    }
    if args.json {
        println!("{json}");
    } else {
        print!("{}", format_table(&report));
    }
    Ok(())
}
