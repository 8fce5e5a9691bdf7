//! Low-poly (after PyTorch-SVGRender's low-poly style): closed polygons with few vertices and
//! flat opaque fills; vertices, colours and the background are trained, opacity stays 1. From
//! scratch: random triangles; from a sample: each traced path becomes the polygon of its
//! segment end points.

use super::{Style, StyleInfo, StyleSpec, random_colour};
use crate::scene::{Point, Rgba, Scene, SceneError, Shape, ShapeKind, Trainable};
use rand::RngExt;

pub struct LowPoly;

/// Vertices of a from-scratch polygon.
pub const LOW_POLY_VERTICES: usize = 3;

static INFO: StyleInfo = StyleInfo {
    name: "low_poly",
    suffix: "low poly art. flat shaded geometric polygons. minimal 2d vector. on a white background. trending on artstation",
    default_paths: 64,
};

impl StyleSpec for LowPoly {
    fn info(&self) -> &'static StyleInfo {
        &INFO
    }

    /// Iconography's groups: vertices, fills, background.
    fn trainable(&self) -> Trainable {
        super::iconography::Iconography.trainable()
    }

    fn opaque_fills(&self) -> bool {
        true
    }

    fn restyle_trace(&self, traced: Scene, _size: u32) -> Result<Scene, SceneError> {
        let mut out = Scene::new(traced.width, traced.height, traced.background)?;
        for s in &traced.shapes {
            let Some(fill) = s.fill else { continue };
            let vertices: Vec<Point> = match s.kind {
                ShapeKind::ClosedCubic => s.points.iter().step_by(3).copied().collect(),
                ShapeKind::Polygon => s.points.clone(),
                ShapeKind::OpenCubic => continue,
            };
            if vertices.len() >= 3 {
                out.shapes
                    .push(Shape::polygon(vertices, Rgba { a: 1.0, ..fill })?);
            }
        }
        Ok(out)
    }

    fn extra_shape(&self, size: u32, rng: &mut dyn rand::Rng) -> Result<Shape, SceneError> {
        let s = size as f32;
        let r = Style::init_radius(size) * 1.5;
        let (cx, cy) = (rng.random::<f32>() * s, rng.random::<f32>() * s);
        let turn = rng.random::<f32>() * std::f32::consts::TAU;
        let vertices = (0..LOW_POLY_VERTICES)
            .map(|i| {
                let a = turn + i as f32 * std::f32::consts::TAU / LOW_POLY_VERTICES as f32;
                Point::new(cx + r * a.cos(), cy + r * a.sin())
            })
            .collect();
        Shape::polygon(vertices, random_colour(rng, 1.0..=1.0))
    }

    fn prune_weak(&self) -> bool {
        true
    }
}
