//! What a run reports besides its SVG: one typed [`RunReport`], shared by the command line's
//! summary, the job's stored result (`detail`), the job view, the events and the page.
//!
//! Its JSON is the job result's `detail` (`openapi.yaml`): sections a run did not have are
//! omitted, and every field defaults when absent, so results and checkpoints stored with
//! fewer fields (or the rerank's old `best`) still read.

use super::spec::{Method, Preset, Style};
use crate::retrieval::Hit;
use crate::scene::Scene;
use crate::stages::live::{LiveResult, StageReport, null_as_nan};
use crate::stages::sds::SdsStats;
use crate::stages::steer::CaptionReport;
use crate::vector::FinishReport;
use crate::vector::check::Editability;
use serde::{Deserialize, Serialize};

/// The result of a run, in process or from a job's child process.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunOutput {
    /// The final scene.
    pub scene: Scene,
    /// The SVG written for `scene`.
    pub svg: String,
    /// Paths in `scene` (`scene.shapes.len()`).
    pub paths: usize,
    pub report: RunReport,
    /// Variations 2..N of a text run asked for more than one (this output is variation 1;
    /// [`RunReport::variations`] summarises them all); empty otherwise.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub variations: Vec<RunOutput>,
}

impl RunOutput {
    /// The output of `scene`, written as `svg`, with `report`.
    pub fn new(scene: Scene, svg: String, report: RunReport) -> Self {
        RunOutput {
            paths: scene.shapes.len(),
            scene,
            svg,
            report,
            variations: Vec::new(),
        }
    }

    /// This output (variation 1) with `others` as variations 2, 3, ...: each in
    /// [`RunOutput::variations`] and all summed up in [`RunReport::variations`] (left empty
    /// when there are no others).
    pub fn with_variations(mut self, others: Vec<RunOutput>) -> Self {
        self.variations = others;
        if !self.variations.is_empty() {
            self.report.variations = std::iter::once(&self)
                .chain(&self.variations)
                .zip(1..)
                .map(|(o, n)| VariationReport::of(n, &o.report, o.paths))
                .collect();
        }
        self
    }

    /// The SVGs of every variation, variation 1 (this output's) first.
    pub fn svgs(&self) -> impl Iterator<Item = &str> {
        std::iter::once(self.svg.as_str()).chain(self.variations.iter().map(|v| v.svg.as_str()))
    }
}

/// One of the results of a text run asked for variations: which sample it was drawn from,
/// that sample's rerank score and its paths.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct VariationReport {
    /// 1-based; variation 1 is the job's `result.svg`.
    pub variation: u32,
    /// Index of the sample it was traced from (`None`: a from-scratch run).
    pub sample: Option<usize>,
    /// The sample's rerank score (`None` without a scorer or samples).
    pub score: Option<f64>,
    /// Paths in its SVG.
    pub paths: usize,
}

impl VariationReport {
    /// The summary of variation `variation` (1-based), reported as `report`, with `paths`.
    pub fn of(variation: u32, report: &RunReport, paths: usize) -> Self {
        let rerank = report.rerank.as_ref();
        VariationReport {
            variation,
            sample: rerank.map(|r| r.chosen),
            score: rerank.and_then(|r| r.scores.get(r.chosen).copied()),
            paths,
        }
    }
}

/// What produced the SVG: a text method, or LIVE for a vectorize run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RunMethod {
    Scratch,
    SdLive,
    SdLiveSds,
    Live,
}

impl From<Method> for RunMethod {
    fn from(m: Method) -> Self {
        match m {
            Method::Scratch => RunMethod::Scratch,
            Method::SdLive => RunMethod::SdLive,
            Method::SdLiveSds => RunMethod::SdLiveSds,
        }
    }
}

/// Where an interrupted run went on from (absent for a run that was not interrupted).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ResumePoint {
    /// The step of score distillation (or of the test executor) it went on from.
    #[serde(rename = "resumed_from")]
    Step(u32),
    /// The number of LIVE stages already done.
    #[serde(rename = "resumed_from_stage")]
    LiveStage(usize),
}

/// The report of a run. Text runs fill the teacher, start, SDS and finish fields; vectorize
/// runs the LIVE ones (`psnr`, `steps`, `stages`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RunReport {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub method: Option<RunMethod>,
    /// The preset of the plan it ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub preset: Option<Preset>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub style: Option<Style>,
    /// The teacher's name and its SDS encoder (`vae`, `taesd`, `pixel`, ...).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub teacher: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub encoder: Option<String>,
    /// The teacher's image size (px).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub size: Option<u32>,
    /// The prompt the teacher was given (the caption with the style's suffix).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub prompt: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub retrieval: Option<RetrievalReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rerank: Option<RerankReport>,
    /// What the run did about the colour and the objects the caption names (captions that
    /// name a colour or two things).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub caption: Option<CaptionReport>,
    /// The LIVE trace a text run started from (a sample or a given image).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub live: Option<TraceReport>,
    /// Random shapes added to a sparse trace so SDS has something to move.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub topped_up: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sds: Option<SdsReport>,
    /// The vector finish after SDS.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub finish: Option<FinishReport>,
    /// Vectorize: PSNR (dB) of the SVG's render against the input.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub psnr: Option<f64>,
    /// Vectorize: Adam steps taken.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub steps: Option<u32>,
    /// The fill paint of a run with gradient fills (absent for flat fills).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fill: Option<crate::vector::fill::FillKind>,
    /// Vectorize: what each LIVE stage did.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub stages: Vec<StageReport>,
    /// What a designer finds in the SVG.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub editability: Option<Editability>,
    /// Text: paths before pruning.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub paths_initial: Option<usize>,
    /// Paths pruned as weak (text) or unseen, over budget or hidden (vectorize).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub paths_pruned: Option<usize>,
    /// Vectorize: paths merged into a touching path of the same fill.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub paths_merged: Option<usize>,
    /// Vectorize: paths that reached past the canvas, cut to it (text runs: `finish.cut`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub paths_cut: Option<usize>,
    /// Paths in the SVG.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub paths_needed: Option<usize>,
    /// Wall-clock seconds of the run (of the last attempt when resumed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seconds: Option<f64>,
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub resumed: Option<ResumePoint>,
    /// Text runs asked for more than one result: every variation, 1 first (empty otherwise).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub variations: Vec<VariationReport>,
    /// What the import of the input SVG could not keep as drawn (ignored filters, broken
    /// reference cycles), one sentence each ([`crate::svg::SvgImport::warnings`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub import_warnings: Vec<String>,
}

impl RunReport {
    /// The report of a LIVE trace of an image (a vectorize run).
    pub fn vectorized(r: &LiveResult) -> Self {
        RunReport {
            method: Some(RunMethod::Live),
            psnr: Some(r.psnr),
            paths_needed: Some(r.paths),
            paths_pruned: Some(r.pruned),
            paths_merged: Some(r.merged),
            paths_cut: Some(r.cut),
            steps: Some(r.steps),
            stages: r.stages.clone(),
            editability: Some(r.editability.clone()),
            ..RunReport::default()
        }
    }
}

/// The CLIP rerank of the K sampled images.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RerankReport {
    /// Scorer name; `None` when no scorer is configured (the first sample is kept).
    pub scorer: Option<String>,
    /// Cosine similarity of each sample with the caption (empty without a scorer).
    pub scores: Vec<f64>,
    /// Index of the kept sample (`best` in results stored before it was named so).
    #[serde(alias = "best")]
    pub chosen: usize,
    pub samples: u32,
    /// Per sample, the retrieved icon it started from (`None`: from noise).
    pub sources: Vec<Option<Hit>>,
    /// Wall-clock seconds of sampling, decoding and reranking the K images.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seconds: Option<f64>,
}

/// Retrieval: which training icons the samples started from.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RetrievalReport {
    /// SDEdit strength of the retrieved starts.
    pub strength: f64,
    /// Share of the K samples started from retrieved icons.
    pub share: f64,
    /// Samples per retrieved icon.
    pub per_caption: u32,
    /// The icons the samples started from.
    pub starts: Vec<Hit>,
    /// The icon the kept sample started from (named in the SVG's metadata).
    pub chosen: Option<Hit>,
    /// Why no sample started from an icon (turned off, no index), if so.
    pub unavailable: Option<String>,
}

/// A LIVE trace at the start of a text run.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TraceReport {
    pub paths: usize,
    #[serde(deserialize_with = "null_as_nan")]
    pub psnr: f64,
    pub pruned: usize,
    pub steps: u32,
    /// Wall-clock seconds of the trace.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seconds: Option<f64>,
}

impl From<&LiveResult> for TraceReport {
    fn from(r: &LiveResult) -> Self {
        TraceReport {
            paths: r.paths,
            psnr: r.psnr,
            pruned: r.pruned,
            steps: r.steps,
            seconds: None,
        }
    }
}

/// Score distillation: the loop's counters and whether renders were augmented.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SdsReport {
    #[serde(flatten)]
    pub stats: SdsStats,
    #[serde(default)]
    pub augment: bool,
    /// Wall-clock seconds of the SDS loop (of the last attempt when resumed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seconds: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_report_reads_back_from_its_json() {
        let report = RunReport {
            method: Some(RunMethod::SdLiveSds),
            rerank: Some(RerankReport {
                scores: vec![0.25, 0.5],
                chosen: 1,
                samples: 2,
                ..RerankReport::default()
            }),
            seconds: Some(1.5),
            resumed: Some(ResumePoint::Step(3)),
            ..RunReport::default()
        };
        let json = serde_json::to_value(&report).unwrap();
        assert_eq!(json["resumed_from"], 3);
        assert_eq!(json["rerank"]["chosen"], 1);
        assert!(
            json.get("sds").is_none(),
            "absent sections are left out: {json}"
        );
        assert_eq!(serde_json::from_value::<RunReport>(json).unwrap(), report);
        let stage = RunReport {
            resumed: Some(ResumePoint::LiveStage(2)),
            ..RunReport::default()
        };
        let json = serde_json::to_string(&stage).unwrap();
        assert_eq!(json, r#"{"resumed_from_stage":2}"#);
        assert_eq!(serde_json::from_str::<RunReport>(&json).unwrap(), stage);
    }

    #[test]
    fn results_stored_in_the_old_shape_still_read() {
        // `best` for the kept sample, non-finite numbers written as null, unknown fields.
        let old = r#"{"method": "sd_live", "preset": "draft", "teacher": "t", "size": 32,
            "rerank": {"scorer": null, "scores": [0.1, 0.3], "best": 1, "samples": 2,
                       "sources": [null, null]},
            "retrieval": {"strength": 0.5, "share": 0.0, "per_caption": 1, "starts": [],
                          "chosen": null, "unavailable": "turned off"},
            "live": {"paths": 4, "psnr": null, "pruned": 0, "steps": 10},
            "sds": {"steps_done": 2, "skipped_nonfinite": 0, "lr_halvings": 0, "reinits": 0,
                    "clipped": 0, "cancelled": false, "last_loss": null, "augment": true},
            "paths_needed": 4, "seconds": 0.5, "executor": "old"}"#;
        let r: RunReport = serde_json::from_str(old).unwrap();
        assert_eq!(r.rerank.as_ref().map(|r| r.chosen), Some(1));
        assert!(r.live.as_ref().is_some_and(|l| l.psnr.is_nan()));
        assert!(
            r.sds
                .as_ref()
                .is_some_and(|s| s.augment && s.stats.last_loss.is_nan())
        );
        assert_eq!(
            r.retrieval.and_then(|r| r.unavailable).as_deref(),
            Some("turned off")
        );
        assert_eq!(r.resumed, None);
        let test_executor: RunReport = serde_json::from_str(r#"{"resumed_from": 0}"#).unwrap();
        assert_eq!(test_executor.resumed, Some(ResumePoint::Step(0)));
    }
}
