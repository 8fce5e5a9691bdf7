//! Running requests the way every entry point does: resolve a [`PlanRequest`] with the
//! executor, then run the plan.

use std::sync::Arc;
use vectorfusion::pipeline::{
    DefaultExecutor, Executor, JobContext, Limits, ModelDirs, PipelineError, PlanRequest, RunInput,
    RunOutput, RunPlan,
};
use vectorfusion::progress::{CancelToken, Progress};

/// An executor over `sd_dir` (and `clip_dir` as the rerank scorer), allowed to download.
pub fn executor(
    sd_dir: std::path::PathBuf,
    clip_dir: Option<std::path::PathBuf>,
) -> DefaultExecutor {
    DefaultExecutor::with_downloads(ModelDirs {
        sd_dir: Some(sd_dir),
        clip_dir,
        ..ModelDirs::default()
    })
}

/// The plan of `req` (default limits); panics on a bad request.
pub fn plan(exec: &DefaultExecutor, req: &PlanRequest) -> RunPlan {
    exec.plan(req, &Limits::default())
        .unwrap_or_else(|e| panic!("{req:?}: {e}"))
}

/// Resolves and runs `req` on `input`, reporting to `sink` and stopping on `cancel`.
pub fn run_with(
    exec: &DefaultExecutor,
    req: &PlanRequest,
    input: &RunInput,
    sink: impl Fn(Progress) + Send + Sync + 'static,
    cancel: CancelToken,
) -> Result<RunOutput, PipelineError> {
    let plan = plan(exec, req);
    let ctx = JobContext::new(Arc::new(sink), cancel, u32::MAX, Box::new(|_| Ok(())), None);
    exec.run_plan(&plan, input, &ctx)
}

/// Resolves and runs a caption request.
pub fn run(exec: &DefaultExecutor, req: &PlanRequest) -> Result<RunOutput, PipelineError> {
    let input = RunInput {
        caption: req.caption.clone(),
        ..RunInput::default()
    };
    run_with(exec, req, &input, |_| {}, CancelToken::new())
}

/// A blank 4 px result (an empty scene and its SVG), for test executors whose output does not
/// matter.
pub fn blank_output() -> RunOutput {
    RunOutput::new(
        vectorfusion::scene::Scene::new(4, 4, vectorfusion::scene::Rgba::TRANSPARENT)
            .expect("a 4 px scene"),
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="4" height="4"/>"#.into(),
        vectorfusion::pipeline::RunReport::default(),
    )
}

/// A written SVG that parses back into a valid scene (and for usvg), without NaN or infinity.
pub fn assert_valid_svg(svg: &str) {
    assert!(svg.starts_with("<svg"), "{svg}");
    assert!(!svg.contains("NaN") && !svg.contains("inf"), "{svg}");
    vectorfusion::svg::from_svg(svg)
        .unwrap()
        .validate()
        .unwrap();
    resvg::usvg::Tree::from_str(svg, &resvg::usvg::Options::default()).unwrap();
}
