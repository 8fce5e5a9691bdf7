//! The job-execution seam, split by job:
//!
//! - [`spec`](JobSpec): what a caller asks for, its vocabularies and [`Limits`];
//! - [`plan`](RunPlan): a request resolved once into every number of the run (presets, model
//!   hints, limits), stored with the job and shown to the caller;
//! - [`presets`](PresetSettings): the preset tables the plan reads;
//! - [`canvas`]: a text run's canvas (aspect or size) and the shape its model samples at;
//! - [`models`](Models): finding and loading the models;
//! - [`executor`](DefaultExecutor): runs plans for the service's workers and the commands;
//! - `text` and `vectorize`: the two kinds of run, wired from the stages;
//! - [`report`](RunReport): what a run reports besides its SVG ([`RunOutput`]).
//!
//! The worker owns queueing, leases, storage and events; an [`Executor`] owns the computation
//! and talks back only through its [`JobContext`] (progress, cancellation, checkpoints).

pub mod canvas;
mod context;
mod error;
mod executor;
mod models;
pub mod plan;
mod presets;
mod report;
mod spec;
mod text;
mod vectorize;

pub use canvas::{Aspect, CanvasPlan, CanvasRequest};
pub use context::{Executor, JobContext};
pub use error::{FailureCode, PipelineError};
pub use executor::{DefaultExecutor, RunInput, request_of};
pub use models::{
    DEFAULT_MODEL_ENV, EMBEDDED_MODEL, EncoderChoice, ModelDirs, Models, NotReady, UnknownEncoder,
    default_model_dir, find_taesd, is_model_dir, is_pixel_model, is_small_model,
    resolve_default_model, resolve_encoder,
};
pub use plan::{
    MAX_VARIATIONS, ModelFacts, PlanRequest, RunPlan, SizeConditioningRequest, StartKind, TextPlan,
    Tuning,
};
pub use presets::PresetSettings;
pub use report::{
    RerankReport, ResumePoint, RetrievalReport, RunMethod, RunOutput, RunReport, SdsReport,
    TraceReport, VariationReport,
};
pub use spec::{
    JobKind, JobSpec, Limits, MAX_JSON_INTEGER, MAX_SEED, Method, PRIORITY_RANGE, Preset,
    SpecError, Style, check_seed, parse_seed,
};
pub use text::{Start, TextCheckpoint, VariationStart, run_text, sample_ranked};
pub use vectorize::{VectorizeCheckpoint, run_vectorize};

#[cfg(test)]
mod tests;
