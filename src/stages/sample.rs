//! Stage 1 of `sd_live*`: K raster samples of the caption, about half of them started from the
//! training icons nearest to it (retrieval, when the model has an index), and the scorer's pick
//! among them (rejection sampling). Sampling itself is the teacher's ([`Teacher::sample`]).

use crate::image::Image;
use crate::models::scorer::{ImageTextScorer, Scorer};
use crate::progress::{CancelToken, ProgressSink};
use crate::retrieval::install::CAPTION_TOKENS;
use crate::retrieval::{Hit, IconIndex};
use crate::teacher::{SampleConfig, SampleError, Teacher};

/// How many of the K samples start from retrieved images: half, rounded up (one of two).
pub fn retrieved_count(k: u32) -> usize {
    k.div_ceil(2) as usize
}

fn failed(what: &str, e: impl std::fmt::Display) -> SampleError {
    SampleError::Failed(format!("{what}: {e}"))
}

/// The K raster samples of one caption and the scorer's pick among them.
///
/// Invariant: `images` is not empty and `best < images.len()` (checked where it is built).
#[derive(Debug, Clone)]
pub struct Ranked {
    images: Vec<Image>,
    best: usize,
    scores: Vec<f32>,
    /// The retrieved icon each sample started from (`None`: from noise); as long as `images`.
    sources: Vec<Option<Hit>>,
}

impl Ranked {
    pub fn images(&self) -> &[Image] {
        &self.images
    }
    /// Index of the kept image (0 without a scorer).
    pub fn best(&self) -> usize {
        self.best
    }
    /// One score per image (empty without a scorer).
    pub fn scores(&self) -> &[f32] {
        &self.scores
    }
    pub fn best_image(&self) -> &Image {
        &self.images[self.best]
    }
    /// Per sample, the icon it started from (`None`: pure noise).
    pub fn sources(&self) -> &[Option<Hit>] {
        &self.sources
    }
    /// The icon the kept sample started from.
    pub fn best_source(&self) -> Option<&Hit> {
        self.sources.get(self.best).and_then(Option::as_ref)
    }
}

/// The training icons of `index` nearest to `caption` to start `n` samples from, rendered at
/// the teacher's image side; `Err` says why there are none (a text encoder that is not the
/// index's MiniLM, ...).
pub fn retrieve(
    teacher: &dyn Teacher,
    index: &IconIndex,
    caption: &str,
    n: usize,
    seed: u64,
) -> Result<Vec<(Hit, Image)>, String> {
    let q = teacher
        .caption_embedding(caption, CAPTION_TOKENS)
        .map_err(|e| e.to_string())?
        .ok_or("the model's text encoder is not the index's MiniLM")?;
    let side = teacher.image_size();
    index
        .nearest(&q, n, 1, seed)
        .map_err(|e| e.to_string())?
        .into_iter()
        .map(|h| {
            let img = index.render(&h.icon, side).map_err(|e| e.to_string())?;
            Ok((h, img))
        })
        .collect()
}

/// Samples `cfg.k` images of `prompt` and keeps the one `scorer` matches best to `caption`.
/// With `index` (`Err`: why there is none, or retrieval is off), [`retrieved_count`] of them
/// start from the training icons nearest to `caption` at `cfg.strength`; the second value says
/// why none did, when none did.
#[allow(clippy::too_many_arguments)]
pub fn sample_and_rerank(
    teacher: &dyn Teacher,
    scorer: Option<&Scorer>,
    index: Result<&IconIndex, String>,
    prompt: &str,
    caption: &str,
    cfg: &SampleConfig,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<(Ranked, Option<String>), SampleError> {
    let (hits, why_not) =
        match index.and_then(|i| retrieve(teacher, i, caption, retrieved_count(cfg.k), cfg.seed)) {
            Ok(h) => (h, None),
            Err(e) => (Vec::new(), Some(e)),
        };
    let (hits, starts): (Vec<Hit>, Vec<Image>) = hits.into_iter().unzip();
    let images = teacher.sample(prompt, &starts, cfg, sink, cancel)?;
    if images.is_empty() {
        return Err(failed("sampling", "no samples drawn (K = 0)"));
    }
    let (best, scores) = match scorer {
        Some(scorer) => scorer
            .best_of(&images, caption)
            .map_err(|e| failed("CLIP rerank", e))?,
        None => (0, Vec::new()),
    };
    if best >= images.len() {
        return Err(failed("rerank", "best index out of range"));
    }
    let mut sources: Vec<Option<Hit>> = hits.into_iter().map(Some).collect();
    sources.resize(images.len(), None);
    Ok((
        Ranked {
            images,
            best,
            scores,
            sources,
        },
        why_not,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn half_the_samples_start_from_retrieval() {
        assert_eq!([1, 2, 3, 8].map(retrieved_count), [1, 1, 2, 4]);
    }
}
