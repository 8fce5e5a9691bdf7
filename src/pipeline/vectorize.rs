//! Image → SVG with LIVE, as a vectorize plan's [`LiveConfig`] says. With a job context the LIVE
//! state is checkpointed after every stage and a restarted job continues from the last one
//! ([`ResumePoint::LiveStage`]), ending with the SVG an uninterrupted run gives.

use super::context::{resume_as, save_checkpoint};
use super::{JobContext, PipelineError, ResumePoint, RunOutput, RunReport};
use crate::image::Image;
use crate::progress::{CancelToken, CheckpointError, ProgressSink};
use crate::stages::live::{self, LiveConfig};
use serde::{Deserialize, Serialize};

/// A vectorize job's saved LIVE state, tagged with the run it belongs to.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct VectorizeCheckpoint {
    /// [`checkpoint_key`]; a state saved for another run is ignored.
    pub key: String,
    pub live: live::LiveState,
}

/// Identifies a vectorize run: the plan's key and the image itself (size and a checksum of its
/// pixels).
pub fn checkpoint_key(plan_key: &str, image: &Image) -> String {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for v in &image.data {
        v.to_bits().hash(&mut h);
    }
    format!(
        "live-v2|{plan_key}|{}x{}|{:016x}",
        image.width,
        image.height,
        h.finish()
    )
}

struct VectorizeCheckpoints<'a> {
    ctx: &'a JobContext,
    key: &'a str,
}

impl live::LiveCheckpoint for VectorizeCheckpoints<'_> {
    fn save(&self, state: &live::LiveState) -> Result<(), CheckpointError> {
        save_checkpoint(
            self.ctx,
            &VectorizeCheckpoint {
                key: self.key.to_string(),
                live: state.clone(),
            },
        )
    }
}

/// Traces `image` with `cfg` (a plan's, keyed `plan_key`).
pub fn run_vectorize(
    image: &Image,
    cfg: &LiveConfig,
    plan_key: &str,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
    ctx: Option<&JobContext>,
) -> Result<RunOutput, PipelineError> {
    let t0 = std::time::Instant::now();
    let key = checkpoint_key(plan_key, image);
    let resume = resume_as::<VectorizeCheckpoint>(ctx)
        .filter(|c| c.key == key)
        .map(|c| c.live);
    let resumed_from = resume.as_ref().map(|s| s.reports.len());
    let hook = ctx.map(|ctx| VectorizeCheckpoints { ctx, key: &key });
    let r = live::vectorize_resumable(
        image,
        cfg,
        sink,
        cancel,
        resume,
        hook.as_ref().map(|h| h as &dyn live::LiveCheckpoint),
    )?;
    let svg = crate::vector::write_svg(&r.scene, &cfg.colors);
    let report = RunReport {
        seconds: Some(t0.elapsed().as_secs_f64()),
        resumed: resumed_from.map(ResumePoint::LiveStage),
        fill: (!cfg.fill.is_flat()).then_some(cfg.fill),
        ..RunReport::vectorized(&r)
    };
    Ok(RunOutput::new(r.scene, svg, report))
}
