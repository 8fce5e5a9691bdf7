//! `init = pixels`: the target's own pixels as grid cells, one square per visible pixel, with
//! no optimisation, written as one outline per region of a colour ([`crate::vector::cells`]):
//! the exact vector copy of pixel art (a sprite, an icon drawn on a grid), which LIVE's curves
//! would round off. Colours: `colors` or a palette snap every cell to it; otherwise near-equal
//! colours merge ([`palette::merge_similar_by_area`]). `target_psnr` and `max_bytes` do not
//! apply ([`LiveConfig::validate`] refuses them). The background is the configured one (`auto`:
//! none, every pixel is a cell).

use super::{LiveConfig, LiveError, LiveResult, MAX_PATHS};
use crate::image::Image;
use crate::scene::{Rgba, Scene, Shape};
use crate::vector::palette::{self, Background};

/// The longest side `init = pixels` takes: a cell per pixel is for pixel art, not photos.
pub const MAX_PIXELS_SIDE: u32 = 256;

/// The pixel copy of `target` (see the module docs).
pub(super) fn trace_pixels(target: &Image, cfg: &LiveConfig) -> Result<LiveResult, LiveError> {
    let (w, h) = (target.width, target.height);
    if w.max(h) > MAX_PIXELS_SIDE {
        return Err(LiveError::Target(format!(
            "init pixels writes a square per pixel, for pixel art: {w}x{h} is larger than \
             {MAX_PIXELS_SIDE} px a side (scale it to its pixel grid first)"
        )));
    }
    let background = match cfg.colors.background {
        Background::Color(c) => c.to_rgba(),
        Background::Transparent | Background::Auto => Rgba::TRANSPARENT,
    };
    let mut scene = Scene::new(w, h, background)?;
    // Straight 8-bit colours, as a PNG holds them and as the SVG writes them.
    let pixels = target.to_rgba8();
    for (i, px) in pixels.chunks_exact(4).enumerate() {
        if px[3] == 0 {
            continue;
        }
        let (x, y) = ((i as u32 % w) as f32, (i as u32 / w) as f32);
        let c = |v: u8| f32::from(v) / 255.0;
        let fill = Rgba::new(c(px[0]), c(px[1]), c(px[2]), c(px[3]));
        scene.shapes.push(Shape::square(x, y, 1.0, fill)?);
    }
    match cfg.colors.resolve(|k| palette::palette_of_image(target, k)) {
        Some(p) => {
            palette::choose_fills(&mut scene, None, &p);
        }
        None => {
            // Cells never overlap: each shows its whole pixel, no render needed to know it.
            let areas = vec![1.0; scene.shapes.len()];
            palette::merge_similar_by_area(&mut scene, &areas, palette::MERGE_DISTANCE);
        }
    }
    let merged = crate::vector::cells::merge_cells(&mut scene);
    if scene.shapes.len() > MAX_PATHS {
        return Err(LiveError::Target(format!(
            "init pixels: the image has {} regions of one colour, more than {MAX_PATHS} paths; \
             fewer colours (colors) make fewer regions",
            scene.shapes.len()
        )));
    }
    scene.validate()?;
    let psnr = crate::image::psnr(&crate::raster::render(&scene), target);
    Ok(LiveResult {
        paths: scene.shapes.len(),
        editability: crate::vector::check::check(&scene),
        scene,
        psnr,
        stages: Vec::new(),
        pruned: 0,
        merged,
        cut: 0,
        steps: 0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vector::palette::{ColorPlan, parse_palette};

    /// A 12×10 sprite: a transparent border, an orange body with a blue 2×2 eye of opacity
    /// `eye` and a one-pixel black dot.
    fn sprite(eye: f32) -> Image {
        let (w, h) = (12u32, 10u32);
        let mut im = Image::filled(w, h, [0.0; 4]);
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let (c, a) = match (x, y) {
                    (3..=4, 3..=4) => ([0.2, 0.4, 1.0], eye),
                    (8, 6) => ([0.0, 0.0, 0.0], 1.0),
                    _ => ([1.0, 0.6, 0.2], 1.0),
                };
                let i = 4 * (y * w + x) as usize;
                let px = [c[0] * a, c[1] * a, c[2] * a, a];
                im.data[i..i + 4].copy_from_slice(&px);
            }
        }
        im
    }

    fn cfg() -> LiveConfig {
        LiveConfig {
            init: super::super::InitMode::Pixels,
            ..LiveConfig::default()
        }
    }

    /// The copy's render against the target: the largest difference of any value.
    fn worst(target: &Image, r: &LiveResult) -> f64 {
        crate::vector::export::diff(&crate::raster::render(&r.scene), target).1
    }

    #[test]
    fn pixel_art_is_copied_exactly_as_one_outline_per_region() {
        let target = sprite(1.0);
        let r = trace_pixels(&target, &cfg()).unwrap();
        // The body (its holes filled, painted first), the eye and the dot.
        assert_eq!(r.paths, 3);
        assert_eq!(r.scene.background, Rgba::TRANSPARENT);
        assert!(r.psnr > 60.0, "{}", r.psnr);
        assert!(worst(&target, &r) < 1e-5);
        assert_eq!(r.editability.self_intersecting, 0);
        assert_eq!(r.steps, 0);
        // A translucent eye would show the body's filled hole: the body is written as
        // rectangles around it instead (7), and the copy stays exact.
        let target = sprite(0.6);
        let r = trace_pixels(&target, &cfg()).unwrap();
        assert_eq!(r.paths, 9);
        assert!(worst(&target, &r) < 1e-5);
    }

    #[test]
    fn a_palette_snaps_every_cell() {
        let mut c = cfg();
        c.colors = ColorPlan {
            palette: Some(parse_palette("#ff9933,#000000").unwrap()),
            ..ColorPlan::default()
        };
        let r = trace_pixels(&sprite(1.0), &c).unwrap();
        let fills: std::collections::BTreeSet<String> = r
            .scene
            .shapes
            .iter()
            .filter_map(|s| s.fill.map(|f| format!("{:.2} {:.2} {:.2}", f.r, f.g, f.b)))
            .collect();
        assert!(fills.len() <= 2, "{fills:?}");
    }

    #[test]
    fn large_images_and_byte_or_psnr_targets_are_refused() {
        let big = Image::filled(MAX_PIXELS_SIDE + 1, 4, [0.0, 0.0, 0.0, 1.0]);
        assert!(matches!(
            trace_pixels(&big, &cfg()),
            Err(LiveError::Target(_))
        ));
        let edge = Image::filled(MAX_PIXELS_SIDE, 4, [0.0, 0.0, 0.0, 1.0]);
        assert_eq!(trace_pixels(&edge, &cfg()).unwrap().paths, 1);
        for c in [
            LiveConfig {
                max_bytes: Some(2000),
                ..cfg()
            },
            LiveConfig {
                target_psnr: Some(30.0),
                ..cfg()
            },
        ] {
            assert!(matches!(c.validate(), Err(LiveError::Config(_))));
        }
    }
}
