//! Colours a designer can work with: a palette parsed from the user's words or found by k-means
//! of the target, each path's fill *chosen* from it by what the path shows, near-equal fills
//! merged, and the background as the user wants it.
//!
//! # The choice of a palette colour
//! Where a path is the visible top layer, the L2 loss of colour `p` over its visible pixels is
//! `Σ w·|t − p|² = Σ w·|t − m|² + W·|m − p|²` (`t` target, `m` the visibility-weighted mean of the
//! target there, `W` the visible weight). So the palette entry nearest to `m` in RGB is the exact
//! minimiser of the loss among the palette for that path, with the geometry fixed: that is what
//! [`choose_fills`] assigns, and the tracer re-chooses after every stage while the geometry is
//! optimised with the fills fixed.

use crate::image::Image;
use crate::scene::{Rgba, Scene};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;
use std::str::FromStr;

/// Most colours a palette (`--palette`) or a colour cap (`--colors`) may name.
pub const MAX_COLORS: usize = 64;

/// Default merge distance of near-equal fills: RGB Euclidean distance in `[0, 1]` units
/// (≈ 4 / 255 per channel), below what a designer tells apart on screen.
pub const MERGE_DISTANCE: f32 = 0.03;

/// Why a colour, palette or background value is not valid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ColorError {
    #[error("{0:?} is not a colour: write #rgb or #rrggbb")]
    Hex(String),
    #[error("the palette is empty")]
    EmptyPalette,
    #[error("the palette has {0} colours; at most {MAX_COLORS}")]
    TooMany(usize),
    #[error("must be between 1 and {MAX_COLORS}, got {0}")]
    Count(u32),
    #[error("{0:?} is not a background: write transparent, auto or #rrggbb")]
    Background(String),
}

/// An opaque 8-bit colour, written `#rrggbb`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Color8(pub [u8; 3]);

impl Color8 {
    pub fn to_rgba(self) -> Rgba {
        let c = |v: u8| v as f32 / 255.0;
        Rgba::new(c(self.0[0]), c(self.0[1]), c(self.0[2]), 1.0)
    }

    pub fn from_rgba(c: Rgba) -> Self {
        let b = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        Color8([b(c.r), b(c.g), b(c.b)])
    }
}

impl fmt::Display for Color8 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "#{:02x}{:02x}{:02x}", self.0[0], self.0[1], self.0[2])
    }
}

impl FromStr for Color8 {
    type Err = ColorError;

    /// `#rgb` or `#rrggbb` (case-insensitive, surrounding spaces ignored).
    fn from_str(s: &str) -> Result<Self, ColorError> {
        let bad = || ColorError::Hex(s.to_string());
        let h = s.trim().strip_prefix('#').ok_or_else(bad)?;
        if !h.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(bad());
        }
        let nib = |i: usize| u8::from_str_radix(&h[i..i + 1], 16).map_err(|_| bad());
        let byte = |i: usize| u8::from_str_radix(&h[i..i + 2], 16).map_err(|_| bad());
        match h.len() {
            3 => Ok(Color8([nib(0)? * 17, nib(1)? * 17, nib(2)? * 17])),
            6 => Ok(Color8([byte(0)?, byte(2)?, byte(4)?])),
            _ => Err(bad()),
        }
    }
}

/// Serde through the type's text form (`Display` out, `FromStr` in): what the CLI and the
/// JSON both read.
macro_rules! serde_as_text {
    ($t:ty) => {
        impl Serialize for $t {
            fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                s.collect_str(self)
            }
        }

        impl<'de> Deserialize<'de> for $t {
            fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                let s = String::deserialize(d)?;
                s.parse().map_err(serde::de::Error::custom)
            }
        }
    };
}

serde_as_text!(Color8);

/// Parses a comma-separated palette such as `"#e63946,#f1faee,#1d3557"`: 1 to [`MAX_COLORS`]
/// colours; repeated colours are kept once, in first-seen order.
pub fn parse_palette(text: &str) -> Result<Vec<Color8>, ColorError> {
    let colours = text
        .split(',')
        .filter(|p| !p.trim().is_empty())
        .map(str::parse)
        .collect::<Result<Vec<Color8>, _>>()?;
    let out = dedup_palette(colours);
    check_palette(&out)?;
    Ok(out)
}

/// `colours` with repeats kept once, in first-seen order.
pub fn dedup_palette(colours: Vec<Color8>) -> Vec<Color8> {
    let mut out: Vec<Color8> = Vec::with_capacity(colours.len());
    for c in colours {
        if !out.contains(&c) {
            out.push(c);
        }
    }
    out
}

/// A palette's size is in `1..=MAX_COLORS`.
pub fn check_palette(p: &[Color8]) -> Result<(), ColorError> {
    match p.len() {
        0 => Err(ColorError::EmptyPalette),
        n if n > MAX_COLORS => Err(ColorError::TooMany(n)),
        _ => Ok(()),
    }
}

/// A colour cap is in `1..=MAX_COLORS`.
pub fn check_colors(n: u32) -> Result<u32, ColorError> {
    if n == 0 || n as usize > MAX_COLORS {
        return Err(ColorError::Count(n));
    }
    Ok(n)
}

/// What is painted behind the paths.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Background {
    /// Nothing: the SVG has no background rectangle.
    Transparent,
    /// A rectangle of the colour the tracer finds at the border (optimised with the paths),
    /// or none when the input's border is transparent.
    #[default]
    Auto,
    /// A rectangle of this colour, not optimised.
    Color(Color8),
}

impl fmt::Display for Background {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Background::Transparent => f.write_str("transparent"),
            Background::Auto => f.write_str("auto"),
            Background::Color(c) => c.fmt(f),
        }
    }
}

impl FromStr for Background {
    type Err = ColorError;

    fn from_str(s: &str) -> Result<Self, ColorError> {
        match s.trim() {
            "transparent" | "none" => Ok(Background::Transparent),
            "auto" => Ok(Background::Auto),
            t if t.starts_with('#') => Ok(Background::Color(t.parse()?)),
            _ => Err(ColorError::Background(s.to_string())),
        }
    }
}

serde_as_text!(Background);

/// The colour settings of a run, in user terms. At most one of `colors` and `palette` is set
/// (checked by [`ColorPlan::validate`]); with neither, near-equal fills are merged.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ColorPlan {
    /// At most this many distinct fills: a palette of this size from k-means of the target.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colors: Option<u32>,
    /// Fills chosen among these colours only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub palette: Option<Vec<Color8>>,
    #[serde(default)]
    pub background: Background,
    /// How the SVG groups its paths.
    #[serde(default)]
    pub group: Grouping,
}

/// How the SVG groups its paths.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Grouping {
    /// One `<path>` after another.
    #[default]
    None,
    /// Runs of paths with the same fill in one `<g>` that carries the fill, with stable ids.
    Color,
    /// Runs of paths added by one LIVE stage in one `<g id="s<k>">` (stage 0: the vtracer
    /// start), paths with stable ids; paths no stage added stay outside groups.
    Stage,
}

impl Grouping {
    /// The SVG options of this grouping at the default precision (ids with any grouping).
    pub fn svg_options(self) -> crate::svg::SvgOptions {
        crate::svg::SvgOptions {
            group_by_color: self == Grouping::Color,
            group_by_stage: self == Grouping::Stage,
            ids: self != Grouping::None,
            ..Default::default()
        }
    }
}

impl ColorPlan {
    /// Checks ranges; the error names the field (`colors`, `palette`).
    pub fn validate(&self) -> Result<(), (&'static str, ColorError)> {
        if let Some(n) = self.colors {
            check_colors(n).map_err(|e| ("colors", e))?;
        }
        if let Some(p) = &self.palette {
            check_palette(p).map_err(|e| ("palette", e))?;
        }
        Ok(())
    }

    /// The palette a run chooses fills from: the user's palette; `colors` colours found by
    /// `found(k)` (k-means of the target or of the fills); both: the user's entries nearest
    /// to `colors` found colours (at most `colors` of them); neither: `None` (free fills).
    pub fn resolve(&self, found: impl FnOnce(usize) -> Vec<Rgba>) -> Option<Vec<Rgba>> {
        let user: Option<Vec<Rgba>> = self
            .palette
            .as_ref()
            .map(|p| p.iter().map(|c| c.to_rgba()).collect());
        match (user, self.colors) {
            (Some(p), Some(k)) if (k as usize) < p.len() => {
                let mut out: Vec<Rgba> = Vec::new();
                for c in found(k as usize) {
                    if let Some(q) = nearest(&p, fill_rgb(Some(c)))
                        && !out.contains(&q)
                    {
                        out.push(q);
                    }
                }
                Some(out)
            }
            (Some(p), _) => Some(p),
            (None, Some(k)) => Some(found(k as usize)),
            (None, None) => None,
        }
    }
}

/// What each path shows: its visible weight (pixels where it is the colour seen, counting
/// partial coverage and what lies above it) and the target's mean colour there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Visible {
    /// Visible area in px² of the scene's canvas.
    pub area: f32,
    /// Visibility-weighted mean of the target (over white); the current fill where `area` is 0
    /// or no target was given.
    pub mean: [f32; 3],
}

/// Coverage (0..1) of one shape alone, per pixel of the scene's canvas, fill and stroke.
fn coverage(scene: &Scene, i: usize) -> Vec<f32> {
    let mut sh = scene.shapes[i].clone();
    if let Some(f) = &mut sh.fill {
        *f = Rgba::new(0.0, 0.0, 0.0, f.a);
    }
    if let Some(s) = &mut sh.stroke {
        s.color = Rgba::new(0.0, 0.0, 0.0, s.color.a);
    }
    let one = Scene {
        width: scene.width,
        height: scene.height,
        background: Rgba::TRANSPARENT,
        shapes: vec![sh],
        groups: Vec::new(),
    };
    crate::raster::render(&one)
        .data
        .chunks_exact(4)
        .map(|p| p[3])
        .collect()
}

fn fill_rgb(c: Option<Rgba>) -> [f32; 3] {
    c.map_or([0.0; 3], |c| [c.r, c.g, c.b])
}

/// [`Visible`] for every shape of `scene`, top layer first in the work but returned in scene
/// order. `target` (the scene's size, premultiplied) gives the means; without it (or at another
/// size) `mean` is the shape's own fill.
pub fn visibility(scene: &Scene, target: Option<&Image>) -> Vec<Visible> {
    let n = scene.width as usize * scene.height as usize;
    let target = target.filter(|t| t.width == scene.width && t.height == scene.height);
    let mut through = vec![1.0f32; n];
    let mut out = vec![
        Visible {
            area: 0.0,
            mean: [0.0; 3]
        };
        scene.shapes.len()
    ];
    for i in (0..scene.shapes.len()).rev() {
        let cov = coverage(scene, i);
        let own = fill_rgb(
            scene.shapes[i]
                .fill
                .or(scene.shapes[i].stroke.map(|s| s.color)),
        );
        let mut w_sum = 0.0f64;
        let mut m = [0.0f64; 3];
        for (p, (&c, t)) in cov.iter().zip(through.iter_mut()).enumerate() {
            if c <= 0.0 {
                continue;
            }
            let w = c * *t;
            *t *= 1.0 - c;
            if w <= 0.0 {
                continue;
            }
            w_sum += w as f64;
            if let Some(tg) = target {
                let q = &tg.data[4 * p..4 * p + 4];
                for k in 0..3 {
                    m[k] += w as f64 * (q[k] + 1.0 - q[3]) as f64;
                }
            }
        }
        let mean = if target.is_some() && w_sum > 0.0 {
            [
                (m[0] / w_sum) as f32,
                (m[1] / w_sum) as f32,
                (m[2] / w_sum) as f32,
            ]
        } else {
            own
        };
        out[i] = Visible {
            area: w_sum as f32,
            mean,
        };
    }
    out
}

fn dist2(a: [f32; 3], b: [f32; 3]) -> f32 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}

fn nearest(palette: &[Rgba], c: [f32; 3]) -> Option<Rgba> {
    palette
        .iter()
        .copied()
        .min_by(|a, b| dist2(fill_rgb(Some(*a)), c).total_cmp(&dist2(fill_rgb(Some(*b)), c)))
}

/// Sets every filled shape's colour to the palette entry that minimises its L2 loss against
/// `target` over the pixels it shows (see the module docs); shapes that show nothing take the
/// entry nearest their current fill. Fill opacity is kept. Strokes of open shapes likewise.
/// Returns how many fills changed.
pub fn choose_fills(scene: &mut Scene, target: Option<&Image>, palette: &[Rgba]) -> usize {
    if palette.is_empty() {
        return 0;
    }
    let vis = visibility(scene, target);
    fills_from(scene, &vis, palette)
}

/// [`choose_fills`] given the scene's [`visibility`] (`vis`, one entry a shape).
fn fills_from(scene: &mut Scene, vis: &[Visible], palette: &[Rgba]) -> usize {
    let mut changed = 0;
    for (sh, v) in scene.shapes.iter_mut().zip(vis) {
        let want = if v.area > 0.0 {
            v.mean
        } else {
            fill_rgb(sh.fill.or(sh.stroke.map(|s| s.color)))
        };
        let Some(p) = nearest(palette, want) else {
            continue;
        };
        let slot = match (&mut sh.fill, &mut sh.stroke) {
            (Some(f), _) => f,
            (None, Some(s)) => &mut s.color,
            (None, None) => continue,
        };
        let new = Rgba::new(p.r, p.g, p.b, slot.a);
        if *slot != new {
            *slot = new;
            changed += 1;
        }
    }
    changed
}

/// The palette entry nearest the background colour (a user palette restricts it too).
pub fn snap_background(scene: &mut Scene, palette: &[Rgba]) {
    if scene.background.a > 0.0
        && let Some(p) = nearest(palette, fill_rgb(Some(scene.background)))
    {
        scene.background = Rgba::new(p.r, p.g, p.b, scene.background.a);
    }
}

/// Deterministic weighted k-means in RGB: `k` centres for `points` with `weights`. Starts from
/// the weighted mean and adds, one at a time, the point farthest (weighted) from the centres so
/// far; then Lloyd iterations until nothing moves or `iters` pass. Fewer than `k` centres when
/// there are fewer distinct points.
pub fn kmeans(points: &[[f32; 3]], weights: &[f32], k: usize, iters: usize) -> Vec<[f32; 3]> {
    let wsum: f64 = weights.iter().map(|&w| w as f64).sum();
    if points.is_empty() || k == 0 || wsum <= 0.0 {
        return Vec::new();
    }
    let mut mean = [0.0f64; 3];
    for (p, &w) in points.iter().zip(weights) {
        for c in 0..3 {
            mean[c] += w as f64 * p[c] as f64;
        }
    }
    let mut centres = vec![[
        (mean[0] / wsum) as f32,
        (mean[1] / wsum) as f32,
        (mean[2] / wsum) as f32,
    ]];
    let mut d: Vec<f32> = points.iter().map(|p| dist2(*p, centres[0])).collect();
    while centres.len() < k {
        let (best, score) = d
            .iter()
            .zip(weights)
            .enumerate()
            .map(|(i, (&d, &w))| (i, d * w))
            .fold((0, 0.0f32), |a, b| if b.1 > a.1 { b } else { a });
        if score <= 0.0 {
            break;
        }
        let c = points[best];
        centres.push(c);
        for (di, p) in d.iter_mut().zip(points) {
            *di = di.min(dist2(*p, c));
        }
    }
    let mut assign = vec![usize::MAX; points.len()];
    for _ in 0..iters {
        let mut moved = false;
        for (a, p) in assign.iter_mut().zip(points) {
            let j = (0..centres.len())
                .min_by(|&x, &y| dist2(*p, centres[x]).total_cmp(&dist2(*p, centres[y])))
                .unwrap_or(0);
            moved |= *a != j;
            *a = j;
        }
        if !moved {
            break;
        }
        let mut acc = vec![[0.0f64; 4]; centres.len()];
        for ((p, &w), &a) in points.iter().zip(weights).zip(&assign) {
            for c in 0..3 {
                acc[a][c] += w as f64 * p[c] as f64;
            }
            acc[a][3] += w as f64;
        }
        for (c, s) in centres.iter_mut().zip(&acc) {
            if s[3] > 0.0 {
                *c = [
                    (s[0] / s[3]) as f32,
                    (s[1] / s[3]) as f32,
                    (s[2] / s[3]) as f32,
                ];
            }
        }
    }
    centres
}

/// A `k`-colour palette of `img` (over white): k-means over a 5-bit-per-channel histogram of
/// its pixels, each bin at its mean colour weighted by its count; centres rounded to 8 bits.
pub fn palette_of_image(img: &Image, k: usize) -> Vec<Rgba> {
    let mut bins: std::collections::BTreeMap<u16, [f64; 4]> = Default::default();
    for p in img.data.chunks_exact(4) {
        let c = [p[0] + 1.0 - p[3], p[1] + 1.0 - p[3], p[2] + 1.0 - p[3]];
        let q = |v: f32| ((v.clamp(0.0, 1.0) * 31.0).round() as u16).min(31);
        let key = (q(c[0]) << 10) | (q(c[1]) << 5) | q(c[2]);
        let e = bins.entry(key).or_default();
        for i in 0..3 {
            e[i] += c[i] as f64;
        }
        e[3] += 1.0;
    }
    let points: Vec<[f32; 3]> = bins
        .values()
        .map(|e| {
            [
                (e[0] / e[3]) as f32,
                (e[1] / e[3]) as f32,
                (e[2] / e[3]) as f32,
            ]
        })
        .collect();
    let weights: Vec<f32> = bins.values().map(|e| e[3] as f32).collect();
    kmeans(&points, &weights, k, 30)
        .into_iter()
        .map(|c| Color8::from_rgba(Rgba::new(c[0], c[1], c[2], 1.0)).to_rgba())
        .collect()
}

/// A `k`-colour palette of the scene's own fills, each weighted by its visible area (for runs
/// without a target image, e.g. after score distillation).
pub fn palette_of_fills(scene: &Scene, k: usize) -> Vec<Rgba> {
    palette_of_visible(&visibility(scene, None), k)
}

/// [`palette_of_fills`] given the scene's [`visibility`] without a target.
fn palette_of_visible(vis: &[Visible], k: usize) -> Vec<Rgba> {
    let points: Vec<[f32; 3]> = vis.iter().map(|v| v.mean).collect();
    let weights: Vec<f32> = vis.iter().map(|v| v.area.max(1e-3)).collect();
    kmeans(&points, &weights, k, 30)
        .into_iter()
        .map(|c| Color8::from_rgba(Rgba::new(c[0], c[1], c[2], 1.0)).to_rgba())
        .collect()
}

/// How close (PSNR, dB, over white) the render with [`fewest_colours`]' palette stays to the
/// render before it.
pub const FEWEST_COLOURS_PSNR: f64 = 35.0;

/// The smallest palette of the scene's own fills ([`palette_of_fills`]: k-means weighted by
/// what each fill shows) whose colours, each fill taking its nearest ([`choose_fills`]),
/// render within `min_psnr` dB of the scene as it is; `None` when no palette smaller than the
/// scene's distinct fills does. The search halves the range of `k` (the error falls with `k`
/// but not strictly: the `k` found passes, and `k − 1` fails or was not tried). A scene with a
/// gradient or texture paint keeps its colours (`None`): those shapes' flat fills are stand-ins
/// that no render shows, as a palette with gradient fills is refused.
pub fn fewest_colours(scene: &Scene, min_psnr: f64) -> Option<Vec<Rgba>> {
    let n = distinct_fills(scene);
    if n < 2 || scene.shapes.iter().any(|s| s.gradients.is_some()) {
        return None;
    }
    let reference = crate::raster::render(scene);
    // What each shape shows depends on the geometry and opacities alone, which no trial
    // changes: one visibility pass serves every palette and every trial's fills.
    let vis = visibility(scene, None);
    let within = |p: &[Rgba]| {
        let mut trial = scene.clone();
        fills_from(&mut trial, &vis, p);
        crate::image::psnr(&crate::raster::render(&trial), &reference) >= min_psnr
    };
    // Smallest passing k in [lo, hi]; `best` the passing palette of the smallest k tried.
    let (mut lo, mut hi) = (1, n - 1);
    let mut best = None;
    while lo <= hi {
        let k = (lo + hi) / 2;
        let p = palette_of_visible(&vis, k);
        if within(&p) {
            best = Some(p);
            hi = k - 1;
        } else {
            lo = k + 1;
        }
    }
    best
}

/// A cluster of [`merge_similar`]: seed colour, weighted colour sum, weight, members.
type Cluster = ([f32; 3], [f64; 3], f64, Vec<usize>);

/// Merges near-equal fills: shapes are visited by visible area, largest first; each joins the
/// first cluster whose colour is within `distance` (RGB Euclidean), else starts one. Every
/// member then takes its cluster's visibility-weighted mean colour (rounded to 8 bits), and
/// near-opaque fills (opacity ≥ 0.97) become opaque. Returns the number of distinct fills left.
pub fn merge_similar(scene: &mut Scene, distance: f32) -> usize {
    let areas: Vec<f32> = visibility(scene, None).iter().map(|v| v.area).collect();
    merge_similar_by_area(scene, &areas, distance)
}

/// [`merge_similar`] with each shape's visible area given (`areas[i]`, px²): for scenes whose
/// visibility is known without rendering, such as pixel cells, which never overlap.
pub fn merge_similar_by_area(scene: &mut Scene, areas: &[f32], distance: f32) -> usize {
    let mut order: Vec<usize> = (0..scene.shapes.len())
        .filter(|&i| scene.shapes[i].fill.is_some())
        .collect();
    order.sort_by(|&a, &b| areas[b].total_cmp(&areas[a]).then(a.cmp(&b)));
    let mut clusters: Vec<Cluster> = Vec::new();
    let d2 = distance * distance;
    for i in order {
        let c = fill_rgb(scene.shapes[i].fill);
        let w = areas[i].max(1e-3) as f64;
        let slot = clusters.iter().position(|cl| dist2(cl.0, c) <= d2);
        let cl = match slot {
            Some(j) => &mut clusters[j],
            None => {
                clusters.push((c, [0.0; 3], 0.0, Vec::new()));
                let last = clusters.len() - 1;
                &mut clusters[last]
            }
        };
        for (acc, v) in cl.1.iter_mut().zip(c) {
            *acc += w * v as f64;
        }
        cl.2 += w;
        cl.3.push(i);
    }
    for (_, s, w, members) in &clusters {
        let mean = Rgba::new((s[0] / w) as f32, (s[1] / w) as f32, (s[2] / w) as f32, 1.0);
        let c = Color8::from_rgba(mean).to_rgba();
        for &i in members {
            if let Some(f) = &mut scene.shapes[i].fill {
                let a = if f.a >= 0.97 { 1.0 } else { f.a };
                *f = Rgba::new(c.r, c.g, c.b, a);
            }
        }
    }
    distinct_fills(scene)
}

/// Distinct fill colours (8-bit, opacity included) of the scene's filled shapes.
pub fn distinct_fills(scene: &Scene) -> usize {
    let mut seen: Vec<(Color8, u8)> = Vec::new();
    for sh in &scene.shapes {
        if let Some(f) = sh.fill {
            let key = (
                Color8::from_rgba(f),
                (f.a.clamp(0.0, 1.0) * 255.0).round() as u8,
            );
            if !seen.contains(&key) {
                seen.push(key);
            }
        }
    }
    seen.len()
}

#[cfg(test)]
#[path = "tests_palette.rs"]
mod tests;
