//! Painting (after PyTorch-SVGRender's painterly styles): open strokes whose points, colour
//! and width are all trained. From scratch: random coloured brush strokes; from a sample: each
//! traced outline becomes a stroke in its fill colour.

use super::sketch::{outlines_as_strokes, random_walk};
use super::{Style, StyleInfo, StyleSpec};
use crate::scene::{Rgba, Scene, SceneError, Shape, Stroke, Trainable};
use rand::RngExt;

/// Strokes of a from-scratch painting at the paper's scale.
pub const PAINTING_STROKES: usize = 48;

pub struct Painting;

/// Brush width on a `size` px canvas: 1–3x the sketch stroke.
fn brush_width(size: u32, k: f32) -> f32 {
    Style::stroke_width(size) * k
}

static INFO: StyleInfo = StyleInfo {
    name: "painting",
    suffix: "a painting with bold brush strokes. vibrant colors. on a white background. trending on artstation",
    default_paths: PAINTING_STROKES,
};

impl StyleSpec for Painting {
    fn info(&self) -> &'static StyleInfo {
        &INFO
    }

    fn trainable(&self) -> Trainable {
        Trainable {
            points: true,
            stroke: true,
            width: true,
            ..Trainable::NONE
        }
    }

    fn restyle_trace(&self, traced: Scene, size: u32) -> Result<Scene, SceneError> {
        outlines_as_strokes(&traced, |s| {
            Stroke::round(
                s.fill.map_or(Rgba::BLACK, |f| Rgba { a: 1.0, ..f }),
                brush_width(size, 2.0),
            )
        })
    }

    fn min_shapes(&self, paths: usize) -> usize {
        paths
    }

    fn extra_shape(&self, size: u32, rng: &mut dyn rand::Rng) -> Result<Shape, SceneError> {
        let pts = random_walk(size, rng);
        let color = Rgba::new(rng.random(), rng.random(), rng.random(), 1.0);
        let width = brush_width(size, rng.random_range(1.0..=3.0));
        Shape::open_cubic(pts, Stroke::round(color, width))
    }
}
