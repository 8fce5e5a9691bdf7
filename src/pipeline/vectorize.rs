//! Image → SVG with LIVE, as a vectorize plan's [`LiveConfig`] says. With a job context the LIVE
//! state is checkpointed after every stage and a restarted job continues from the last one
//! (`detail.resumed_from_stage`), ending with the SVG an uninterrupted run gives.

use super::context::{resume_as, save_checkpoint};
use super::text::MethodOutput;
use super::{JobContext, PipelineError};
use crate::image::Image;
use crate::progress::{CancelToken, ProgressSink};
use crate::stages::live::{self, LiveConfig};
use serde::{Deserialize, Serialize};
use serde_json::json;

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
    fn save(&self, state: &live::LiveState) -> Result<(), String> {
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
) -> Result<MethodOutput, PipelineError> {
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
    let mut detail = json!({
        "method": "live",
        "psnr": r.psnr,
        "paths_needed": r.paths,
        "paths_pruned": r.pruned,
        "steps": r.steps,
        "stages": r.stages,
        "editability": r.editability,
    });
    if let Some(n) = resumed_from {
        detail["resumed_from_stage"] = json!(n);
    }
    Ok(MethodOutput {
        paths: r.scene.shapes.len(),
        scene: r.scene,
        svg,
        detail,
    })
}
