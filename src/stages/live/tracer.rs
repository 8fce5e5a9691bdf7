//! The vtracer baseline and `--init vtracer`: trace with the `vtracer` crate, turn its compound
//! paths into simple closed cubic paths of our scene, and render any SVG with resvg for
//! fidelity measurements.

use crate::image::Image;
use crate::losses::polygon_area;
use crate::scene::{Point, Rgba, Scene, Shape};
use resvg::tiny_skia;
use visioncortex::{CompoundPathElement, PathSimplifyMode};

/// A vtracer setting used as a baseline or initialiser.
#[derive(Clone, Debug, PartialEq)]
pub struct TracerSetting {
    /// Spline (default) or polygon outlines.
    pub polygon: bool,
    /// Speckles smaller than `filter_speckle^2` pixels are dropped (vtracer default 4).
    pub filter_speckle: usize,
    /// Significant bits per colour channel (vtracer default 6).
    pub color_precision: i32,
    /// Colour difference between gradient layers (vtracer default 16).
    pub layer_difference: i32,
}

impl Default for TracerSetting {
    /// vtracer's defaults (spline mode).
    fn default() -> Self {
        Self {
            polygon: false,
            filter_speckle: 4,
            color_precision: 6,
            layer_difference: 16,
        }
    }
}

impl TracerSetting {
    fn to_config(&self) -> vtracer::Config {
        vtracer::Config {
            mode: if self.polygon {
                PathSimplifyMode::Polygon
            } else {
                PathSimplifyMode::Spline
            },
            filter_speckle: self.filter_speckle,
            color_precision: self.color_precision,
            layer_difference: self.layer_difference,
            ..vtracer::Config::default()
        }
    }

    /// Short label for reports, e.g. `spline s4 p6 d16`.
    pub fn label(&self) -> String {
        format!(
            "{} s{} p{} d{}",
            if self.polygon { "polygon" } else { "spline" },
            self.filter_speckle,
            self.color_precision,
            self.layer_difference
        )
    }
}

/// vtracer's output: the SVG text and the traced compound paths with their colours.
pub struct Traced {
    pub svg: String,
    pub file: vtracer::SvgFile,
}

impl Traced {
    /// Number of `<path>` elements (vtracer's notion of a path; each may hold many segments
    /// and holes).
    pub fn path_count(&self) -> usize {
        self.file.paths.len()
    }
}

/// Traces `image` (its straight-alpha RGBA, so transparent regions are keyed out as vtracer
/// does for its own users).
pub fn trace(image: &Image, setting: &TracerSetting) -> Result<Traced, String> {
    let img = vtracer::ColorImage {
        pixels: image.to_rgba8(),
        width: image.width as usize,
        height: image.height as usize,
    };
    let file = vtracer::convert(img, setting.to_config())?;
    Ok(Traced {
        svg: file.to_string(),
        file,
    })
}

/// Renders SVG text with resvg at `width x height` (the SVG's own size is scaled to fit) into a
/// premultiplied image.
pub fn render_svg(svg: &str, width: u32, height: u32) -> Result<Image, crate::svg::RenderError> {
    let tree = crate::svg::parse_usvg(svg)?;
    let mut pixmap = crate::svg::pixmap(width, height)?;
    let s = tree.size();
    let (kx, ky) = (width as f32 / s.width(), height as f32 / s.height());
    resvg::render(
        &tree,
        tiny_skia::Transform::from_scale(kx, ky),
        &mut pixmap.as_mut(),
    );
    let mut im = Image::new(width, height);
    for (d, s) in im.data.iter_mut().zip(pixmap.data()) {
        *d = *s as f32 / 255.0;
    }
    Ok(im)
}

/// Resamples a closed polyline to `n` points evenly spaced by arc length.
fn resample(poly: &[(f32, f32)], n: usize) -> Vec<(f32, f32)> {
    let m = poly.len();
    let seg_len = |i: usize| {
        let (a, b) = (poly[i], poly[(i + 1) % m]);
        ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt()
    };
    let total: f32 = (0..m).map(seg_len).sum();
    if total <= 0.0 || m < 2 {
        return vec![poly.first().copied().unwrap_or((0.0, 0.0)); n];
    }
    let mut out = Vec::with_capacity(n);
    let (mut i, mut acc) = (0usize, 0.0f32);
    for k in 0..n {
        let target = total * k as f32 / n as f32;
        while i < m - 1 && acc + seg_len(i) < target {
            acc += seg_len(i);
            i += 1;
        }
        let l = seg_len(i).max(1e-6);
        let t = ((target - acc) / l).clamp(0.0, 1.0);
        let (a, b) = (poly[i], poly[(i + 1) % m]);
        out.push((a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t));
    }
    out
}

/// A closed cubic path through `pts` (Catmull-Rom handles, so the curve stays smooth).
fn smooth_closed(pts: &[(f32, f32)], fill: Rgba) -> Option<Shape> {
    let n = pts.len();
    if n < 3 {
        return None;
    }
    let mut out = Vec::with_capacity(3 * n);
    for i in 0..n {
        let p0 = pts[(i + n - 1) % n];
        let p1 = pts[i];
        let p2 = pts[(i + 1) % n];
        let p3 = pts[(i + 2) % n];
        out.push(Point::new(p1.0, p1.1));
        out.push(Point::new(
            p1.0 + (p2.0 - p0.0) / 6.0,
            p1.1 + (p2.1 - p0.1) / 6.0,
        ));
        out.push(Point::new(
            p2.0 - (p3.0 - p1.0) / 6.0,
            p2.1 - (p3.1 - p1.1) / 6.0,
        ));
    }
    Shape::closed_cubic(out, fill).ok()
}

/// Outer outlines of vtracer's paths as simple closed cubic paths, bottom to top, each resampled
/// to between 4 and `max_segments` segments (about one per 16 px of perimeter). Holes are
/// dropped (in vtracer's stacked mode the layers above cover them). If there are more than
/// `max_paths` outlines, the smallest are merged away (dropped) first, keeping paint order.
/// A bottom outline covering at least 90% of the canvas becomes the scene background instead
/// of a path.
pub fn traced_to_scene(
    traced: &Traced,
    width: u32,
    height: u32,
    max_paths: usize,
    max_segments: usize,
) -> Result<Scene, crate::scene::SceneError> {
    let mut candidates: Vec<(f32, Shape)> = Vec::new();
    for p in &traced.file.paths {
        let c = p.color;
        let fill = Rgba::new(
            c.r as f32 / 255.0,
            c.g as f32 / 255.0,
            c.b as f32 / 255.0,
            c.a as f32 / 255.0,
        );
        // The first element of a compound path is its outer boundary.
        let Some(first) = p.path.paths.first() else {
            continue;
        };
        let mut poly: Vec<(f32, f32)> = match first {
            CompoundPathElement::PathI32(q) => {
                q.path.iter().map(|v| (v.x as f32, v.y as f32)).collect()
            }
            CompoundPathElement::PathF64(q) => {
                q.path.iter().map(|v| (v.x as f32, v.y as f32)).collect()
            }
            // Spline anchors every third point are a good polygon of the outline.
            CompoundPathElement::Spline(q) => q
                .points
                .iter()
                .step_by(3)
                .map(|v| (v.x as f32, v.y as f32))
                .collect(),
        };
        if poly.len() > 1 && poly.first() == poly.last() {
            poly.pop();
        }
        if poly.len() < 3 {
            continue;
        }
        let area = polygon_area(&poly).abs();
        let perimeter: f32 = (0..poly.len())
            .map(|i| {
                let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
                ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt()
            })
            .sum();
        let n = ((perimeter / 16.0).round() as usize).clamp(4, max_segments.max(4));
        if let Some(shape) = smooth_closed(&resample(&poly, n), fill.clamped()) {
            candidates.push((area, shape));
        }
    }
    let mut background = Rgba::WHITE;
    if let Some((area, first)) = candidates.first()
        && *area >= 0.9 * (width * height) as f32
        && let Some(f) = first.fill
        && f.a >= 1.0
    {
        background = f;
        candidates.remove(0);
    }
    if candidates.len() > max_paths {
        let mut by_area: Vec<usize> = (0..candidates.len()).collect();
        by_area.sort_by(|&a, &b| candidates[b].0.total_cmp(&candidates[a].0).then(a.cmp(&b)));
        let mut keep = vec![false; candidates.len()];
        for &i in by_area.iter().take(max_paths) {
            keep[i] = true;
        }
        candidates = candidates
            .into_iter()
            .zip(keep)
            .filter_map(|(c, k)| k.then_some(c))
            .collect();
    }
    let mut scene = Scene::new(width, height, background)?;
    scene.shapes = candidates.into_iter().map(|(_, s)| s).collect();
    scene.validate()?;
    Ok(scene)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_squares() -> Image {
        let (red, blue) = ([1.0, 0.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0]);
        super::super::tests::white_with_rects(48, &[(6..26, 6..26, red), (30..44, 28..44, blue)])
    }

    #[test]
    fn vtracer_round_trip_through_resvg_is_faithful() {
        let im = two_squares();
        for polygon in [false, true] {
            let t = trace(
                &im,
                &TracerSetting {
                    polygon,
                    ..Default::default()
                },
            )
            .unwrap();
            assert!(t.path_count() >= 2);
            let back = render_svg(&t.svg, 48, 48).unwrap();
            let p = crate::image::psnr(&im, &back);
            assert!(p > 20.0, "polygon={polygon} psnr {p}");
        }
    }

    #[test]
    fn traced_scene_has_simple_closed_paths_of_the_right_colours() {
        let im = two_squares();
        let t = trace(&im, &TracerSetting::default()).unwrap();
        let scene = traced_to_scene(&t, 48, 48, 64, 12).unwrap();
        assert!(scene.shapes.len() >= 2);
        for s in &scene.shapes {
            assert!(s.num_segments() >= 4 && s.num_segments() <= 12);
        }
        assert!(
            scene
                .shapes
                .iter()
                .any(|s| s.fill.unwrap().r > 0.9 && s.fill.unwrap().b < 0.1)
        );
        assert!(
            scene
                .shapes
                .iter()
                .any(|s| s.fill.unwrap().b > 0.9 && s.fill.unwrap().r < 0.1)
        );
        let limited = traced_to_scene(&t, 48, 48, 1, 12).unwrap();
        assert_eq!(limited.shapes.len(), 1);
    }

    #[test]
    fn resample_is_even() {
        let sq = [(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)];
        let r = resample(&sq, 8);
        assert_eq!(r.len(), 8);
        assert_eq!(r[1], (2.0, 0.0));
        assert_eq!(r[2], (4.0, 0.0));
        assert_eq!(r[5], (2.0, 4.0));
    }
}
