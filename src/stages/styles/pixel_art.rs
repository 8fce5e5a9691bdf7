//! Pixel art (VectorFusion): a fixed 32x32 grid of squares whose colours alone are trained,
//! with a saturation penalty; a sampled image starts it by L1 pixelation.

#![allow(clippy::needless_range_loop)] // index loops read clearest in pixel code

use super::{SampleStart, StyleInfo, StyleSpec};
use crate::image::Image;
use crate::optim::{GroupSchedules, LrSchedule};
use crate::scene::{Rgba, Scene, SceneError, Shape, Trainable};
use rand::RngExt;

/// Pixel-art grid side (cells per row and column).
pub const PIXEL_GRID: u32 = 32;

pub struct PixelArt;

static INFO: StyleInfo = StyleInfo {
    name: "pixel_art",
    suffix: "pixel art. trending on artstation",
    default_paths: (PIXEL_GRID * PIXEL_GRID) as usize,
};

impl StyleSpec for PixelArt {
    fn info(&self) -> &'static StyleInfo {
        &INFO
    }

    fn preset_paths(&self, _preset_paths: usize) -> usize {
        self.default_paths()
    }

    fn trainable(&self) -> Trainable {
        Trainable {
            fill: true,
            ..Trainable::NONE
        }
    }

    /// Colours only: warm-up 1e-5 → 1e-4 over 1000 steps, then constant.
    fn schedules(&self, steps: u32) -> GroupSchedules {
        let colours = LrSchedule::WarmupCosine {
            start: 1e-5,
            peak: 1e-4,
            warmup: 1000,
            end: 1e-4,
            total: steps.max(1001),
        };
        GroupSchedules {
            points: LrSchedule::Constant { lr: 0.0 },
            fill: colours.clone(),
            stroke: colours,
            width: LrSchedule::Constant { lr: 0.0 },
            background: LrSchedule::Constant { lr: 0.0 },
            paint_geometry: LrSchedule::zero(),
            paint_stops: LrSchedule::zero(),
        }
    }

    fn saturation_penalty(&self) -> f32 {
        0.05
    }

    /// The grid, whatever `paths` says.
    fn init_shapes(
        &self,
        size: u32,
        _paths: usize,
        rng: &mut dyn rand::Rng,
        out: &mut Vec<Shape>,
    ) -> Result<(), SceneError> {
        let cell = size as f32 / PIXEL_GRID as f32;
        for gy in 0..PIXEL_GRID {
            for gx in 0..PIXEL_GRID {
                let c = Rgba::new(rng.random(), rng.random(), rng.random(), 1.0);
                out.push(Shape::square(gx as f32 * cell, gy as f32 * cell, cell, c)?);
            }
        }
        Ok(())
    }

    fn sample_start(&self) -> SampleStart {
        SampleStart::Image
    }

    fn scene_from_image(&self, image: &Image, size: u32) -> Result<Scene, SceneError> {
        pixelate_l1(image, size)
    }

    fn extra_shape(&self, size: u32, _rng: &mut dyn rand::Rng) -> Result<Shape, SceneError> {
        let cell = size as f32 / PIXEL_GRID as f32;
        Shape::square(0.0, 0.0, cell, Rgba::WHITE)
    }
}

/// L1 pixelation: the 32x32 pixel-art scene whose cell colours minimise the L1 distance to
/// `image` (per-channel median of each cell's pixels, composited over white). Used to initialise
/// pixel art from a sampled image.
pub fn pixelate_l1(image: &Image, size: u32) -> Result<Scene, SceneError> {
    let mut scene = Scene::new(size, size, Rgba::WHITE)?;
    let cell = size as f32 / PIXEL_GRID as f32;
    let (w, h) = (image.width as usize, image.height as usize);
    for gy in 0..PIXEL_GRID as usize {
        for gx in 0..PIXEL_GRID as usize {
            let x0 = gx * w / PIXEL_GRID as usize;
            let x1 = ((gx + 1) * w / PIXEL_GRID as usize).max(x0 + 1).min(w);
            let y0 = gy * h / PIXEL_GRID as usize;
            let y1 = ((gy + 1) * h / PIXEL_GRID as usize).max(y0 + 1).min(h);
            let mut rgb = [0.0f32; 3];
            for (c, out) in rgb.iter_mut().enumerate() {
                let mut vals: Vec<f32> = Vec::new();
                for y in y0..y1 {
                    for x in x0..x1 {
                        let p = &image.data[4 * (y * w + x)..4 * (y * w + x) + 4];
                        vals.push(p[c] + 1.0 - p[3]);
                    }
                }
                vals.sort_by(f32::total_cmp);
                *out = vals.get(vals.len() / 2).copied().unwrap_or(1.0);
            }
            let fill = Rgba::new(rgb[0], rgb[1], rgb[2], 1.0).clamped();
            scene.shapes.push(Shape::square(
                gx as f32 * cell,
                gy as f32 * cell,
                cell,
                fill,
            )?);
        }
    }
    Ok(scene)
}
