//! Output styles. [`Style`] names one; its [`StyleSpec`] (one file per style) says everything
//! the stages need to know about it: prompt suffix, shape counts, trainable groups, learning
//! rates, the from-scratch scene, how a sampled raster becomes the starting scene, re-init and
//! pruning. Stages ask the spec and never `match` on a style, so a new style is one file here
//! plus its variant (and the OpenAPI enum).
//!
//! Sizes in the paper are for a 512 px canvas (render 600, crop 512); here geometric defaults
//! (circle radius 20 px, stroke width 6 px) scale with `size / 512` and are clamped to stay
//! visible on the small canvases tests use.

mod iconography;
mod low_poly;
mod painting;
mod pixel_art;
mod sketch;

pub use pixel_art::{PIXEL_GRID, pixelate_l1};
pub use sketch::{SKETCH_SEGMENTS, SKETCH_STROKES, random_stroke};

use crate::image::Image;
use crate::optim::{GroupSchedules, LrSchedule};
use crate::scene::{Rgba, Scene, SceneError, Shape, Trainable};
use rand::{Rng, RngExt};
use serde::{Deserialize, Serialize};

/// An output style. Serialised, read (HTTP, stored jobs, JSON summaries) and printed in its one
/// canonical spelling, snake_case (`pixel_art`); the command line ([`std::str::FromStr`]) also
/// takes any case, `-` or spaces for `_`, and the [`Style::ALIASES`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Style {
    /// Closed 4-segment filled paths (points, fills and background trainable).
    #[default]
    Iconography,
    /// A fixed 32x32 grid of squares; only colours trainable.
    PixelArt,
    /// Open black strokes; only points trainable.
    Sketch,
    /// Closed polygons with few vertices and flat opaque fills.
    LowPoly,
    /// Open strokes with trainable colour, width and points.
    Painting,
}

impl Style {
    /// Other names the command line accepts; the API takes the canonical names only, so a
    /// client generated from its spec has one value per style.
    pub const ALIASES: [(&'static str, Style); 7] = [
        ("icon", Style::Iconography),
        ("flat", Style::Iconography),
        ("pixelart", Style::PixelArt),
        ("pixel", Style::PixelArt),
        ("line", Style::Sketch),
        ("lowpoly", Style::LowPoly),
        ("paint", Style::Painting),
    ];

    pub const ALL: [Style; 5] = [
        Style::Iconography,
        Style::PixelArt,
        Style::Sketch,
        Style::LowPoly,
        Style::Painting,
    ];

    /// The canonical name (`pixel_art`).
    pub fn as_str(self) -> &'static str {
        self.spec().name()
    }

    /// What the stages need to know about this style.
    pub fn spec(self) -> &'static dyn StyleSpec {
        match self {
            Style::Iconography => &iconography::Iconography,
            Style::PixelArt => &pixel_art::PixelArt,
            Style::Sketch => &sketch::Sketch,
            Style::LowPoly => &low_poly::LowPoly,
            Style::Painting => &painting::Painting,
        }
    }

    /// The paper's prompt suffix for this style.
    pub fn suffix(self) -> &'static str {
        self.spec().suffix()
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
        self.spec().default_paths()
    }

    /// Which parameter groups are optimised.
    pub fn trainable(self) -> Trainable {
        self.spec().trainable()
    }

    /// The learning-rate schedules for a run of `steps` steps.
    pub fn schedules(self, steps: u32) -> GroupSchedules {
        self.spec().schedules(steps)
    }

    /// A random from-scratch scene of `size x size` px with `paths` shapes.
    pub fn init_scene<R: Rng>(
        self,
        size: u32,
        paths: usize,
        rng: &mut R,
    ) -> Result<Scene, SceneError> {
        let mut scene = Scene::new(size, size, Rgba::WHITE)?;
        self.spec()
            .init_shapes(size, paths, rng, &mut scene.shapes)?;
        Ok(scene)
    }

    /// Circle radius for random initial paths on a `size` px canvas (20 px at 512).
    pub fn init_radius(size: u32) -> f32 {
        (20.0 * size as f32 / 512.0).max(3.0)
    }

    /// Stroke width on a `size` px canvas (6 px at 512).
    pub fn stroke_width(size: u32) -> f32 {
        (6.0 * size as f32 / 512.0).max(1.5)
    }
}

impl std::str::FromStr for Style {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let word = s.trim().to_ascii_lowercase().replace(['-', ' '], "_");
        if let Some((_, style)) = Style::ALIASES.iter().find(|(a, _)| *a == word) {
            return Ok(*style);
        }
        Style::deserialize(serde_json::Value::String(word)).map_err(|_| {
            let names: Vec<&str> = Style::ALL.iter().map(|s| s.as_str()).collect();
            format!("unknown style {s:?} (expected {})", names.join(", "))
        })
    }
}

impl std::fmt::Display for Style {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// How a sampled raster becomes a style's starting scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleStart {
    /// Trace it with LIVE, then [`StyleSpec::restyle_trace`].
    Trace,
    /// [`StyleSpec::scene_from_image`] directly (pixel art's L1 pixelation).
    Image,
}

/// A style's name, prompt suffix and default shape count.
#[derive(Debug)]
pub struct StyleInfo {
    /// Canonical name (snake_case, as serialised).
    pub name: &'static str,
    /// The prompt suffix (VectorFusion's for its three styles).
    pub suffix: &'static str,
    /// Shapes of a from-scratch run at the paper's scale.
    pub default_paths: usize,
}

/// Everything about a style that the stages use. Implementations are unit structs, one file
/// each; [`Style::spec`] maps the enum to them.
pub trait StyleSpec: Send + Sync {
    fn info(&self) -> &'static StyleInfo;
    /// Canonical name (snake_case, as serialised).
    fn name(&self) -> &'static str {
        self.info().name
    }
    /// The prompt suffix.
    fn suffix(&self) -> &'static str {
        self.info().suffix
    }
    /// Shapes of a from-scratch run at the paper's scale.
    fn default_paths(&self) -> usize {
        self.info().default_paths
    }
    /// Shapes of a preset run whose preset asks for `preset_paths` paths.
    fn preset_paths(&self, preset_paths: usize) -> usize {
        preset_paths
    }
    /// Parameter groups SDS optimises.
    fn trainable(&self) -> Trainable;
    /// Learning-rate schedules of a run of `steps` steps.
    fn schedules(&self, steps: u32) -> GroupSchedules {
        paper_schedules(steps)
    }
    /// Fill opacity stays 1 (the opacity gradient is dropped).
    fn opaque_fills(&self) -> bool {
        false
    }
    /// Faint closed cubic paths are re-initialised during SDS (and tiny ones after a trace).
    fn reinit_faint_paths(&self) -> bool {
        false
    }
    /// Weight of the saturation penalty on the render (pixel art).
    fn saturation_penalty(&self) -> f32 {
        0.0
    }
    /// Weight of LIVE's self-intersection loss on closed cubic paths.
    fn xing_weight(&self) -> f32 {
        0.0
    }
    /// Appends the shapes of a `size` px from-scratch scene of `paths` shapes: by default
    /// `paths` of [`StyleSpec::extra_shape`].
    fn init_shapes(
        &self,
        size: u32,
        paths: usize,
        rng: &mut dyn rand::Rng,
        out: &mut Vec<Shape>,
    ) -> Result<(), SceneError> {
        for _ in 0..paths {
            out.push(self.extra_shape(size, rng)?);
        }
        Ok(())
    }
    /// How a sampled image becomes the starting scene.
    fn sample_start(&self) -> SampleStart {
        SampleStart::Trace
    }
    /// A LIVE trace (closed cubic fills, already at `size` px) in this style.
    fn restyle_trace(&self, traced: Scene, _size: u32) -> Result<Scene, SceneError> {
        Ok(traced)
    }
    /// The starting scene drawn directly from a sampled image ([`SampleStart::Image`]).
    fn scene_from_image(&self, image: &Image, size: u32) -> Result<Scene, SceneError> {
        let _ = image;
        Scene::new(size, size, Rgba::WHITE)
    }
    /// Fewest shapes a starting scene of a `paths`-path run needs; a flat sample that traces
    /// to fewer is topped up with [`StyleSpec::extra_shape`] so SDS has something to move.
    fn min_shapes(&self, _paths: usize) -> usize {
        1
    }
    /// One random shape: of a from-scratch scene, or topping up a starting scene.
    fn extra_shape(&self, size: u32, rng: &mut dyn rand::Rng) -> Result<Shape, SceneError>;
    /// Faint and tiny filled shapes are pruned from the final scene.
    fn prune_weak(&self) -> bool {
        false
    }
}

/// The paper's schedules: points warm-up 0.02 → 0.2 over 500 steps, cosine to 0.05 at the end;
/// colours (and gradient stops) 20x lower; widths 2x lower; background 200x lower; gradient
/// geometry as the points.
pub fn paper_schedules(steps: u32) -> GroupSchedules {
    let points = LrSchedule::WarmupCosine {
        start: 0.02,
        peak: 0.2,
        warmup: 500,
        end: 0.05,
        total: steps.max(501),
    };
    GroupSchedules {
        fill: points.scaled(1.0 / 20.0),
        stroke: points.scaled(1.0 / 20.0),
        width: points.scaled(0.5),
        background: points.scaled(1.0 / 200.0),
        // Gradient geometry is in pixels like the points, its stops in [0, 1] like colours.
        paint_geometry: points.clone(),
        paint_stops: points.scaled(1.0 / 20.0),
        points,
    }
}

/// A random colour with opacity in `alpha`.
fn random_colour(rng: &mut dyn rand::Rng, alpha: std::ops::RangeInclusive<f32>) -> Rgba {
    Rgba::new(
        rng.random(),
        rng.random(),
        rng.random(),
        rng.random_range(alpha),
    )
}

/// A random closed 4-segment circle (radius from [`Style::init_radius`]) with a random colour
/// and opacity in `U(0.7, 1)`: the from-scratch init and the re-init of faint paths.
pub fn random_circle<R: Rng + ?Sized>(size: u32, rng: &mut R) -> Result<Shape, SceneError> {
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

#[cfg(test)]
mod tests;
