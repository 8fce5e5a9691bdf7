//! Iconography (VectorFusion): closed 4-segment cubic paths with flat fills; points, fills and
//! the background are trained; faint paths are re-initialised and pruned.

use super::{StyleInfo, StyleSpec, random_circle};
use crate::scene::{SceneError, Shape, Trainable};

pub struct Iconography;

static INFO: StyleInfo = StyleInfo {
    name: "iconography",
    suffix: "minimal flat 2d vector icon. lineal color. on a white background. trending on artstation",
    default_paths: 64,
};

impl StyleSpec for Iconography {
    fn info(&self) -> &'static StyleInfo {
        &INFO
    }

    fn trainable(&self) -> Trainable {
        Trainable {
            points: true,
            fill: true,
            background: true,
            ..Trainable::NONE
        }
    }

    fn reinit_faint_paths(&self) -> bool {
        true
    }

    fn xing_weight(&self) -> f32 {
        0.01
    }

    fn extra_shape(&self, size: u32, rng: &mut dyn rand::Rng) -> Result<Shape, SceneError> {
        random_circle(size, rng)
    }

    fn prune_weak(&self) -> bool {
        true
    }
}
