//! Sketch (VectorFusion): open black strokes of fixed width; only the points are trained. A
//! sampled image is traced and every outline becomes a stroke.

use super::{Style, StyleInfo, StyleSpec};
use crate::scene::{Point, Rgba, Scene, SceneError, Shape, ShapeKind, Stroke, Trainable};
use rand::RngExt;

/// Number of strokes in the paper.
pub const SKETCH_STROKES: usize = 16;
/// Segments per stroke.
pub const SKETCH_SEGMENTS: usize = 5;

pub struct Sketch;

static INFO: StyleInfo = StyleInfo {
    name: "sketch",
    suffix: "minimal 2d line drawing. trending on artstation",
    default_paths: SKETCH_STROKES,
};

impl StyleSpec for Sketch {
    fn info(&self) -> &'static StyleInfo {
        &INFO
    }

    fn preset_paths(&self, preset_paths: usize) -> usize {
        preset_paths.min(SKETCH_STROKES)
    }

    fn trainable(&self) -> Trainable {
        Trainable {
            points: true,
            ..Trainable::NONE
        }
    }

    fn restyle_trace(&self, traced: Scene, size: u32) -> Result<Scene, SceneError> {
        outlines_as_strokes(&traced, |_| {
            Stroke::round(Rgba::BLACK, Style::stroke_width(size))
        })
    }

    fn min_shapes(&self, paths: usize) -> usize {
        paths
    }

    fn extra_shape(&self, size: u32, rng: &mut dyn rand::Rng) -> Result<Shape, SceneError> {
        random_stroke(size, rng)
    }
}

/// Every closed outline of `scene` as an open stroke (`stroke` of the shape it came from).
pub(super) fn outlines_as_strokes(
    scene: &Scene,
    stroke: impl Fn(&Shape) -> Stroke,
) -> Result<Scene, SceneError> {
    let mut out = Scene::new(scene.width, scene.height, Rgba::WHITE)?;
    for s in &scene.shapes {
        if s.kind != ShapeKind::ClosedCubic || s.points.is_empty() {
            continue;
        }
        let mut pts = s.points.clone();
        pts.push(s.points[0]);
        out.shapes.push(Shape::open_cubic(pts, stroke(s))?);
    }
    Ok(out)
}

/// A random walk of [`SKETCH_SEGMENTS`] cubic segments (CLIPDraw style) from a random point.
pub(super) fn random_walk<R: rand::Rng + ?Sized>(size: u32, rng: &mut R) -> Vec<Point> {
    let s = size as f32;
    let step = 0.1 * s;
    let mut p = Point::new(rng.random::<f32>() * s, rng.random::<f32>() * s);
    let mut pts = vec![p];
    for _ in 0..3 * SKETCH_SEGMENTS {
        p = Point::new(
            (p.x + rng.random_range(-step..=step)).clamp(0.0, s),
            (p.y + rng.random_range(-step..=step)).clamp(0.0, s),
        );
        pts.push(p);
    }
    pts
}

/// A random open black stroke of [`SKETCH_SEGMENTS`] segments: a short random walk (CLIPDraw
/// style) starting at a random point.
pub fn random_stroke<R: rand::Rng + ?Sized>(size: u32, rng: &mut R) -> Result<Shape, SceneError> {
    Shape::open_cubic(
        random_walk(size, rng),
        Stroke::round(Rgba::BLACK, Style::stroke_width(size)),
    )
}
