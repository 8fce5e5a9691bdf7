//! Steering the sample stage toward what the caption names ([`CaptionPlan`]) where the prior
//! does not: retrieval for the object's words (not the colour's), starts recoloured into the
//! caption's colour, two objects' icons composed into one start, samples of the right colour
//! ranked first, the kept sample recoloured. How far is the model's `_colour_steer`
//! ([`ColourSteer`]); the run's [`CaptionReport`] says what was done.

use super::sample::{NoStarts, RetrievalPick, nearest, render_hits};
use crate::caption::colour::dominant;
use crate::caption::compose::compose;
use crate::caption::recolour::recolour_image;
use crate::caption::{CaptionPlan, ColourName, ColourSteer, Hue};
use crate::image::Image;
use crate::retrieval::{Hit, IconIndex};
use crate::teacher::Teacher;
use serde::{Deserialize, Serialize};

/// A training caption this close (cosine of MiniLM embeddings) to the whole caption names the
/// same thing ("blue square", "woman with veil"): its icons are retrieved as they are.
pub const KNOWN_NAME: f32 = 0.9;

/// What the run did with the caption's colour and objects (the run report's `caption`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CaptionReport {
    /// The colour the caption names.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub colour: Option<ColourName>,
    /// The things it names.
    pub objects: Vec<String>,
    /// The words the icons were retrieved for, when not the whole caption.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub retrieved_for: Vec<String>,
    /// Per retrieved start, the family moved into the caption's colour (`null`: kept).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub starts_recoloured: Vec<Option<Hue>>,
    /// The second object's icon of each composed start.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub composed_with: Vec<Hit>,
    /// Each sample's largest hue family.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sample_families: Vec<Option<Hue>>,
    /// The family of the kept sample moved into the caption's colour before tracing.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sample_recoloured: Option<Hue>,
    /// The family of the final SVG's fills moved into the caption's colour.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub svg_recoloured: Option<Hue>,
    /// What the caption asks for that this run cannot draw.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub limits: Vec<String>,
}

impl CaptionReport {
    /// The report of `plan` before any stage ran: what it names, and the limit of a
    /// two-object caption sampled from noise.
    pub fn of(plan: &CaptionPlan, retrieving: bool) -> Self {
        let objects: Vec<String> = plan.objects.iter().map(|o| o.words.clone()).collect();
        let mut limits = Vec::new();
        if plan.is_pair() && (!retrieving || plan.steer < ColourSteer::Start) {
            limits.push(format!(
                "the caption names two things ({}); without retrieval the model draws one \
                 picture for the whole caption and may leave one out",
                objects.join(", ")
            ));
        }
        CaptionReport {
            colour: plan.colour(),
            objects,
            limits,
            ..CaptionReport::default()
        }
    }
}

/// `images` recoloured toward `colour` (when there is one); the family each moved.
fn recoloured(images: &mut [Image], colour: Option<ColourName>) -> Vec<Option<Hue>> {
    images
        .iter_mut()
        .map(|img| colour.and_then(|c| recolour_image(img, c)))
        .collect()
}

/// The retrieved starts for `caption` as `plan` steers them (`plan.steer` at least
/// [`ColourSteer::Start`]): the whole caption's icons, as they are, when a training caption
/// names it ([`KNOWN_NAME`]); else the object's icons (each pair of the two objects' icons
/// composed), recoloured into each object's colour. Fills `report`.
pub fn steered_starts(
    teacher: &dyn Teacher,
    index: &IconIndex,
    caption: &str,
    plan: &CaptionPlan,
    pick: RetrievalPick,
    report: &mut CaptionReport,
) -> Result<Vec<(Hit, Image)>, NoStarts> {
    let side = teacher.image_size();
    let whole = nearest(teacher, index, caption, pick)?;
    if whole.first().is_some_and(|h| h.similarity >= KNOWN_NAME) || plan.objects.is_empty() {
        // Drawings of exactly this caption ("black heart"): started from as they are.
        let images = render_hits(index, &whole, side)?;
        return Ok(whole.into_iter().zip(images).collect());
    }
    let first = &plan.objects[0];
    let hits = nearest(teacher, index, &first.words, pick)?;
    let mut images = render_hits(index, &hits, side)?;
    report.retrieved_for.push(first.words.clone());
    let mut moved = recoloured(&mut images, first.colour);
    if let (Some(second), Some(relation)) = (plan.objects.get(1), plan.relation) {
        let others = nearest(teacher, index, &second.words, pick)?;
        let mut other_images = render_hits(index, &others, side)?;
        report.retrieved_for.push(second.words.clone());
        let other_moved = recoloured(&mut other_images, second.colour);
        for (i, img) in images.iter_mut().enumerate() {
            let j = i % other_images.len().max(1);
            if let Some(other) = other_images.get(j) {
                *img = compose(img, other, relation);
                report.composed_with.push(others[j].clone());
                moved[i] = moved[i].or(other_moved[j]);
            }
        }
    }
    report.starts_recoloured = moved;
    Ok(hits.into_iter().zip(images).collect())
}

/// The sample to keep: with a colour to rank by, the best-scored of those whose largest family
/// is the colour's (all of them when none is); else `scored_best`. `families` is each sample's
/// largest family.
pub fn colour_first(
    scores: &[f32],
    scored_best: usize,
    families: &[Option<Hue>],
    colour: Option<ColourName>,
) -> usize {
    let Some(want) = colour.map(|c| c.hue) else {
        return scored_best;
    };
    let right = |i: usize| families.get(i).copied().flatten() == Some(want);
    if !(0..families.len()).any(right) || scores.len() != families.len() {
        return scored_best;
    }
    (0..scores.len())
        .filter(|&i| right(i))
        .max_by(|&a, &b| scores[a].total_cmp(&scores[b]).then(b.cmp(&a)))
        .unwrap_or(scored_best)
}

/// After the rerank: each sample's family in `report`, the kept one chosen colour-first and
/// recoloured as `plan.steer` says. Returns the index to keep.
pub fn steer_samples(
    images: &mut [Image],
    scores: &[f32],
    best: usize,
    plan: &CaptionPlan,
    report: &mut CaptionReport,
) -> usize {
    report.sample_families = images.iter().map(dominant).collect();
    // Two objects of two colours: no one colour for the whole picture.
    let colour = plan.colour().filter(|_| !plan.is_pair());
    let best = if plan.steer >= ColourSteer::Rerank {
        colour_first(scores, best, &report.sample_families, colour)
    } else {
        best
    };
    if plan.steer >= ColourSteer::Sample
        && let (Some(c), Some(img)) = (colour, images.get_mut(best))
    {
        report.sample_recoloured = recolour_image(img, c);
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    const BLUE: Option<ColourName> = Some(ColourName {
        hue: Hue::Blue,
        shade: None,
    });

    #[test]
    fn samples_of_the_colour_rank_first() {
        let scores = [0.4, 0.3, 0.2];
        let fam = [Some(Hue::Red), Some(Hue::Blue), Some(Hue::Blue)];
        assert_eq!(colour_first(&scores, 0, &fam, BLUE), 1);
        // None of the colour: the scorer's pick; no colour: the scorer's pick.
        let red = [Some(Hue::Red), Some(Hue::Green), None];
        assert_eq!(colour_first(&scores, 0, &red, BLUE), 0);
        assert_eq!(colour_first(&scores, 0, &fam, None), 0);
    }
}
