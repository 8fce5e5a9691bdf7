//! Stage 1 of `sd_live*`: K raster samples of the caption, a share of them (the model's
//! `_retrieval_share`, half by default) started from the training icons nearest to it
//! (retrieval, when the model has an index), and the scorer's pick among them (rejection
//! sampling). Sampling itself is the teacher's ([`Teacher::sample`]).

use super::steer::{CaptionReport, steer_samples, steered_starts};
use crate::caption::{CaptionPlan, ColourSteer};
use crate::image::Image;
use crate::models::scorer::{ImageTextScorer, Scorer};
use crate::progress::{CancelToken, ProgressSink};
use crate::retrieval::install::CAPTION_TOKENS;
use crate::retrieval::{Hit, IconIndex, RetrievalError};
use crate::teacher::{SampleConfig, SampleError, Teacher, TeacherError};

/// Why a run starts from no retrieved icon (reported as the retrieval's `unavailable`).
#[derive(Debug, thiserror::Error)]
pub enum NoStarts {
    #[error("turned off")]
    Off,
    #[error("the model's _retrieval_share is 0")]
    NoShare,
    #[error("the model pins no icon sets")]
    NoIconSets,
    #[error("the test teacher has no retrieval index")]
    TestTeacher,
    #[error("the model's text encoder is not the index's MiniLM")]
    NotMiniLm,
    #[error("the retrieved icons are square and the sample is {w}x{h}")]
    NotSquare { w: u32, h: u32 },
    #[error("text embedding: {0}")]
    Embedding(#[source] TeacherError),
    #[error(transparent)]
    Retrieval(#[from] RetrievalError),
}

/// How many of the K samples start from retrieved images: `share` of them, rounded up (share
/// 0.5: one of two, two of four), at most K. `share` outside `0..=1` (or NaN) is clamped to it.
pub fn retrieved_count(k: u32, share: f64) -> usize {
    let share = if share.is_nan() {
        0.0
    } else {
        share.clamp(0.0, 1.0)
    };
    // A small tolerance so that 0.5 × 4 stays 2 whatever the rounding of `share`.
    ((f64::from(k) * share - 1e-9).ceil().max(0.0) as usize).min(k as usize)
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
    /// What the stage did about the caption's colour and objects (captions that name any).
    caption: Option<CaptionReport>,
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
    /// What the stage did about the caption's colour and objects.
    pub fn caption(&self) -> Option<&CaptionReport> {
        self.caption.as_ref()
    }
    /// The icon the kept sample started from.
    pub fn best_source(&self) -> Option<&Hit> {
        self.sources.get(self.best).and_then(Option::as_ref)
    }

    /// The indices of the `n` best samples, best first: the kept one, then the others by
    /// score (highest first; in sampling order without a scorer), skipping a sample equal to
    /// one already picked while enough others are left. At most K.
    pub fn top(&self, n: usize) -> Vec<usize> {
        let score = |i: usize| self.scores.get(i).copied().unwrap_or(0.0);
        let mut rest: Vec<usize> = (0..self.images.len()).filter(|&i| i != self.best).collect();
        rest.sort_by(|&a, &b| score(b).total_cmp(&score(a)));
        let mut picks = vec![self.best];
        let mut same = Vec::new();
        for i in rest {
            if picks.iter().any(|&p| self.images[p] == self.images[i]) {
                same.push(i);
            } else {
                picks.push(i);
            }
        }
        picks.extend(same);
        picks.truncate(n.max(1));
        picks
    }
}

/// Which icons of an index a run starts from: how many, at most how many drawings of one
/// caption, and the seed that picks among a caption's drawings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RetrievalPick {
    pub n: usize,
    pub per_caption: usize,
    pub seed: u64,
}

/// The training icons of `index` nearest to `caption` to start `pick.n` samples from, rendered
/// at the teacher's image side; `Err` says why there are none (a text encoder that is not the
/// index's MiniLM, ...).
pub fn retrieve(
    teacher: &dyn Teacher,
    index: &IconIndex,
    caption: &str,
    pick: RetrievalPick,
) -> Result<Vec<(Hit, Image)>, NoStarts> {
    let hits = nearest(teacher, index, caption, pick)?;
    let (w, h) = teacher.image_dims();
    if w != h {
        return Err(NoStarts::NotSquare { w, h });
    }
    let images = render_hits(index, &hits, teacher.image_size())?;
    Ok(hits.into_iter().zip(images).collect())
}

/// The icons of `index` nearest to `text` (by the teacher's MiniLM embedding), unrendered.
pub(super) fn nearest(
    teacher: &dyn Teacher,
    index: &IconIndex,
    text: &str,
    pick: RetrievalPick,
) -> Result<Vec<Hit>, NoStarts> {
    let q = teacher
        .caption_embedding(text, CAPTION_TOKENS)
        .map_err(NoStarts::Embedding)?
        .ok_or(NoStarts::NotMiniLm)?;
    Ok(index.nearest(&q, pick.n, pick.per_caption, pick.seed)?)
}

/// The icons of `hits` rendered at `side` px.
pub fn render_hits(
    index: &IconIndex,
    hits: &[Hit],
    side: u32,
) -> Result<Vec<Image>, RetrievalError> {
    hits.iter().map(|h| index.render(&h.icon, side)).collect()
}

/// The starts of the retrieved samples: the caption's nearest icons, or as `steer` says
/// ([`steered_starts`]; steering fills `report`).
fn starts(
    teacher: &dyn Teacher,
    (index, pick): (&IconIndex, RetrievalPick),
    caption: &str,
    steer: Option<&CaptionPlan>,
    report: &mut Option<CaptionReport>,
) -> Result<Vec<(Hit, Image)>, NoStarts> {
    match (steer, report.as_mut()) {
        (Some(plan), Some(r)) if plan.steer >= ColourSteer::Start => {
            steered_starts(teacher, index, caption, plan, pick, r)
        }
        _ => retrieve(teacher, index, caption, pick),
    }
}

/// Samples `cfg.k` images of `prompt` and keeps the one `scorer` matches best to `caption`.
/// With `retrieval` (an index and which of its icons to start from: `n` of them,
/// [`retrieved_count`]; `Err`: why there is none, or retrieval is off), that many start from the
/// training icons nearest to `caption` at `cfg.strength`; the second value says why none did,
/// when none did. With `steer` (what the caption names beyond its embedding), the starts, the
/// pick and the kept sample are steered toward it ([`super::steer`]).
#[allow(clippy::too_many_arguments)]
pub fn sample_and_rerank(
    teacher: &dyn Teacher,
    scorer: Option<&Scorer>,
    retrieval: Result<(&IconIndex, RetrievalPick), &NoStarts>,
    prompt: &str,
    caption: &str,
    steer: Option<&CaptionPlan>,
    cfg: &SampleConfig,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<(Ranked, Option<String>), SampleError> {
    let mut report = steer.map(|p| CaptionReport::of(p, retrieval.is_ok()));
    let found = retrieval.map(|r| starts(teacher, r, caption, steer, &mut report));
    let (hits, why_not) = match found {
        Ok(Ok(h)) => (h, None),
        Ok(Err(e)) => (Vec::new(), Some(e.to_string())),
        Err(e) => (Vec::new(), Some(e.to_string())),
    };
    let (hits, starts): (Vec<Hit>, Vec<Image>) = hits.into_iter().unzip();
    let mut images = teacher.sample(prompt, &starts, cfg, sink, cancel)?;
    if images.is_empty() {
        return Err(SampleError::failed("sampling", "no samples drawn (K = 0)"));
    }
    let (mut best, scores) = match scorer {
        Some(scorer) => scorer
            .best_of(&images, caption)
            .map_err(|e| SampleError::failed("CLIP rerank", e))?,
        None => (0, Vec::new()),
    };
    if let (Some(plan), Some(r)) = (steer, report.as_mut()) {
        best = steer_samples(&mut images, &scores, best, plan, r);
    }
    if best >= images.len() {
        return Err(SampleError::failed("rerank", "best index out of range"));
    }
    let mut sources: Vec<Option<Hit>> = hits.into_iter().map(Some).collect();
    sources.resize(images.len(), None);
    Ok((
        Ranked {
            images,
            best,
            scores,
            sources,
            caption: report,
        },
        why_not,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(v: f32) -> Image {
        Image::filled(2, 2, [v, v, v, 1.0])
    }

    #[test]
    fn the_top_samples_are_the_kept_one_then_by_score_and_distinct() {
        let ranked = Ranked {
            images: vec![flat(0.1), flat(0.2), flat(0.1), flat(0.3)],
            best: 1,
            scores: vec![0.5, 0.9, 0.8, 0.2],
            sources: vec![None; 4],
            caption: None,
        };
        assert_eq!(ranked.top(1), [1]);
        // Sample 0 scores higher than 3 but equals sample 2 (picked before it): it comes after
        // the distinct ones.
        assert_eq!(ranked.top(3), [1, 2, 3]);
        assert_eq!(ranked.top(4), [1, 2, 3, 0]);
        assert_eq!(ranked.top(9), [1, 2, 3, 0]);
        let unscored = Ranked {
            scores: Vec::new(),
            best: 0,
            ..ranked
        };
        assert_eq!(unscored.top(3), [0, 1, 3]);
    }

    #[test]
    fn a_share_of_the_samples_start_from_retrieval() {
        let half = |k| retrieved_count(k, 0.5);
        assert_eq!([1, 2, 3, 4, 8].map(half), [1, 1, 2, 2, 4]);
        let all = |k| retrieved_count(k, 1.0);
        assert_eq!([1, 2, 3, 8].map(all), [1, 2, 3, 8]);
        assert_eq!([0, 1, 4].map(|k| retrieved_count(k, 0.0)), [0, 0, 0]);
        // Out of range shares are clamped; K = 0 retrieves nothing.
        assert_eq!(retrieved_count(4, 7.0), 4);
        assert_eq!(retrieved_count(4, -1.0), 0);
        assert_eq!(retrieved_count(4, f64::NAN), 0);
        assert_eq!(retrieved_count(0, 1.0), 0);
        assert_eq!(retrieved_count(3, 0.25), 1);
    }
}
