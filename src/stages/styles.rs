//! VectorFusion's three styles: scene initialisation, trainable groups, learning-rate schedules
//! and prompt suffixes.
//!
//! Sizes in the paper are for a 512 px canvas (render 600, crop 512); here geometric defaults
//! (circle radius 20 px, stroke width 6 px) scale with `size / 512` and are clamped to stay
//! visible on the small canvases tests use.

#![allow(clippy::needless_range_loop)] // index loops read clearest in pixel code

use crate::image::Image;
use crate::optim::{GroupSchedules, LrSchedule};
use crate::scene::{Point, Rgba, Scene, SceneError, Shape, Stroke, Trainable};
use rand::{Rng, RngExt};
use serde::{Deserialize, Serialize};

/// An output style.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Style {
    /// Closed 4-segment filled paths (points, fills and background trainable).
    Iconography,
    /// A fixed 32x32 grid of squares; only colours trainable.
    PixelArt,
    /// Open black strokes; only points trainable.
    Sketch,
}

impl std::str::FromStr for Style {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().replace(['-', ' '], "_").as_str() {
            "iconography" | "icon" | "flat" => Ok(Style::Iconography),
            "pixel_art" | "pixelart" | "pixel" => Ok(Style::PixelArt),
            "sketch" | "line" => Ok(Style::Sketch),
            other => Err(format!(
                "unknown style {other:?} (expected iconography, pixel-art or sketch)"
            )),
        }
    }
}

impl std::fmt::Display for Style {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Style::Iconography => "iconography",
            Style::PixelArt => "pixel-art",
            Style::Sketch => "sketch",
        })
    }
}

/// Pixel-art grid side (cells per row and column).
pub const PIXEL_GRID: u32 = 32;
/// Sketch: number of strokes in the paper.
pub const SKETCH_STROKES: usize = 16;
/// Sketch: segments per stroke.
pub const SKETCH_SEGMENTS: usize = 5;

impl Style {
    pub const ALL: [Style; 3] = [Style::Iconography, Style::PixelArt, Style::Sketch];

    /// The paper's prompt suffix for this style.
    pub fn suffix(self) -> &'static str {
        match self {
            Style::Iconography => {
                "minimal flat 2d vector icon. lineal color. on a white background. trending on artstation"
            }
            Style::PixelArt => "pixel art. trending on artstation",
            Style::Sketch => "minimal 2d line drawing. trending on artstation",
        }
    }

    /// `caption` with the style suffix appended.
    pub fn prompt(self, caption: &str) -> String {
        self.prompt_with(caption, true)
    }

    /// [`Style::prompt`], or the bare trimmed caption without `suffix` (a model trained on bare
    /// captions, `ModelHints::style_suffix`).
    pub fn prompt_with(self, caption: &str, suffix: bool) -> String {
        if !suffix {
            return caption.trim().to_string();
        }
        let c = caption.trim().trim_end_matches('.');
        format!("{c}. {}", self.suffix())
    }

    /// Default number of shapes (paths, cells or strokes).
    pub fn default_paths(self) -> usize {
        match self {
            Style::Iconography => 64,
            Style::PixelArt => (PIXEL_GRID * PIXEL_GRID) as usize,
            Style::Sketch => SKETCH_STROKES,
        }
    }

    /// Which parameter groups are optimised.
    pub fn trainable(self) -> Trainable {
        match self {
            Style::Iconography => Trainable {
                points: true,
                fill: true,
                background: true,
                ..Trainable::NONE
            },
            Style::PixelArt => Trainable {
                fill: true,
                ..Trainable::NONE
            },
            Style::Sketch => Trainable {
                points: true,
                ..Trainable::NONE
            },
        }
    }

    /// Whether faint paths are re-initialised during optimisation (filled free-form paths only).
    pub fn reinit_faint_paths(self) -> bool {
        matches!(self, Style::Iconography)
    }

    /// The paper's learning-rate schedules for a run of `steps` steps.
    ///
    /// Points: warm-up 0.02 → 0.2 over 500 steps, cosine to 0.05 at the end; colours 20x lower;
    /// background 200x lower. Pixel art (colours only): warm-up 1e-5 → 1e-4 over 1000 steps, then
    /// constant.
    pub fn schedules(self, steps: u32) -> GroupSchedules {
        let points = LrSchedule::WarmupCosine {
            start: 0.02,
            peak: 0.2,
            warmup: 500,
            end: 0.05,
            total: steps.max(501),
        };
        match self {
            Style::PixelArt => {
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
                }
            }
            _ => GroupSchedules {
                fill: points.scaled(1.0 / 20.0),
                stroke: points.scaled(1.0 / 20.0),
                width: points.scaled(0.5),
                background: points.scaled(1.0 / 200.0),
                points,
            },
        }
    }

    /// Circle radius for random initial paths on a `size` px canvas (20 px at 512).
    pub fn init_radius(size: u32) -> f32 {
        (20.0 * size as f32 / 512.0).max(3.0)
    }

    /// Sketch stroke width on a `size` px canvas (6 px at 512).
    pub fn stroke_width(size: u32) -> f32 {
        (6.0 * size as f32 / 512.0).max(1.5)
    }

    /// A random from-scratch scene of `size x size` px with `paths` shapes (ignored for pixel art,
    /// which always has a 32x32 grid).
    pub fn init_scene<R: Rng>(
        self,
        size: u32,
        paths: usize,
        rng: &mut R,
    ) -> Result<Scene, SceneError> {
        let mut scene = Scene::new(size, size, Rgba::WHITE)?;
        match self {
            Style::Iconography => {
                for _ in 0..paths {
                    scene.shapes.push(random_circle(size, rng)?);
                }
            }
            Style::PixelArt => {
                let cell = size as f32 / PIXEL_GRID as f32;
                for gy in 0..PIXEL_GRID {
                    for gx in 0..PIXEL_GRID {
                        let c = Rgba::new(rng.random(), rng.random(), rng.random(), 1.0);
                        scene.shapes.push(Shape::square(
                            gx as f32 * cell,
                            gy as f32 * cell,
                            cell,
                            c,
                        )?);
                    }
                }
            }
            Style::Sketch => {
                for _ in 0..paths {
                    scene.shapes.push(random_stroke(size, rng)?);
                }
            }
        }
        Ok(scene)
    }
}

/// A random closed 4-segment circle (radius from [`Style::init_radius`]) with a random colour
/// and opacity in `U(0.7, 1)`: the from-scratch init and the re-init of faint paths.
pub fn random_circle<R: Rng>(size: u32, rng: &mut R) -> Result<Shape, SceneError> {
    let s = size as f32;
    let fill = Rgba::new(
        rng.random(),
        rng.random(),
        rng.random(),
        rng.random_range(0.7..=1.0),
    );
    Shape::circle(
        rng.random::<f32>() * s,
        rng.random::<f32>() * s,
        Style::init_radius(size),
        4,
        fill,
    )
}

/// A random open black stroke of [`SKETCH_SEGMENTS`] segments: a short random walk (CLIPDraw
/// style) starting at a random point.
pub fn random_stroke<R: Rng>(size: u32, rng: &mut R) -> Result<Shape, SceneError> {
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
    Shape::open_cubic(
        pts,
        Stroke {
            color: Rgba::BLACK,
            width: Style::stroke_width(size),
        },
    )
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn init_scenes_follow_the_paper() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let icon = Style::Iconography.init_scene(512, 64, &mut rng).unwrap();
        assert_eq!(icon.shapes.len(), 64);
        for s in &icon.shapes {
            assert_eq!(s.num_segments(), 4);
            assert!(s.is_closed());
            let a = s.fill.unwrap().a;
            assert!((0.7..=1.0).contains(&a));
            let (lo, hi) = s.control_bounds();
            assert!((hi.x - lo.x - 40.0).abs() < 1.0, "radius 20 at 512 px");
        }
        let px = Style::PixelArt.init_scene(64, 0, &mut rng).unwrap();
        assert_eq!(px.shapes.len(), 1024);
        assert_eq!(px.shapes[33].points[0], Point::new(2.0, 2.0));
        let sk = Style::Sketch.init_scene(512, 16, &mut rng).unwrap();
        assert_eq!(sk.shapes.len(), 16);
        for s in &sk.shapes {
            assert_eq!(s.num_segments(), 5);
            let st = s.stroke.unwrap();
            assert_eq!((st.color, st.width), (Rgba::BLACK, 6.0));
        }
        for sc in [&icon, &px, &sk] {
            assert!(sc.validate().is_ok());
        }
    }

    #[test]
    fn schedules_and_masks() {
        let s = Style::Iconography.schedules(2000);
        assert!((s.points.lr(0) - 0.02).abs() < 1e-7);
        assert!((s.points.lr(500) - 0.2).abs() < 1e-6);
        assert!((s.points.lr(2000) - 0.05).abs() < 1e-6);
        assert!((s.fill.lr(500) - 0.01).abs() < 1e-6);
        assert!((s.background.lr(500) - 0.001).abs() < 1e-6);
        let p = Style::PixelArt.schedules(3000);
        assert!((p.fill.lr(0) - 1e-5).abs() < 1e-9);
        assert!((p.fill.lr(1000) - 1e-4).abs() < 1e-9);
        assert!((p.fill.lr(2500) - 1e-4).abs() < 1e-9);
        assert!(!Style::PixelArt.trainable().points);
        assert!(Style::Sketch.trainable().points && !Style::Sketch.trainable().fill);
    }

    #[test]
    fn prompts_and_parsing() {
        assert_eq!(
            Style::PixelArt.prompt("a cat."),
            "a cat. pixel art. trending on artstation"
        );
        assert_eq!("pixel-art".parse::<Style>().unwrap(), Style::PixelArt);
        assert!("oil".parse::<Style>().is_err());
        for s in Style::ALL {
            assert_eq!(s.to_string().parse::<Style>().unwrap(), s);
        }
    }

    #[test]
    fn pixelation_takes_cell_medians() {
        let mut im = Image::filled(64, 64, [1.0, 1.0, 1.0, 1.0]);
        // Cell (1, 0) is 2x2 px: three red pixels and one blue → median red.
        for (x, y, c) in [
            (2, 0, [1.0, 0.0, 0.0, 1.0]),
            (3, 0, [1.0, 0.0, 0.0, 1.0]),
            (2, 1, [1.0, 0.0, 0.0, 1.0]),
            (3, 1, [0.0, 0.0, 1.0, 1.0]),
        ] {
            im.data[4 * (y * 64 + x)..4 * (y * 64 + x) + 4].copy_from_slice(&c);
        }
        let sc = pixelate_l1(&im, 64).unwrap();
        assert_eq!(sc.shapes[1].fill.unwrap(), Rgba::new(1.0, 0.0, 0.0, 1.0));
        assert_eq!(sc.shapes[0].fill.unwrap(), Rgba::WHITE);
    }
}
