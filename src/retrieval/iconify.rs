//! Iconify JSON icon sets (`@iconify-json/*` packages' `icons.json`): each icon as a standalone
//! SVG document, rendered with resvg to a square RGB image over white.

use crate::image::Image;
use crate::svg::RenderError;
use resvg::tiny_skia;
use serde_json::Value;

/// Why a text is not an iconify JSON set.
#[derive(Debug, thiserror::Error)]
pub enum IconSetError {
    #[error("not an iconify JSON set: {0}")]
    Json(#[source] serde_json::Error),
    #[error("not an iconify JSON set: no \"icons\" object")]
    NoIcons,
}

/// One icon of a set: its name and a standalone SVG document.
#[derive(Debug, Clone, PartialEq)]
pub struct IconSvg {
    pub name: String,
    pub svg: String,
}

fn num(v: &Value, key: &str, default: f64) -> f64 {
    v.get(key).and_then(Value::as_f64).unwrap_or(default)
}

/// The icons of an iconify JSON set, sorted by name (`aliases` are skipped, as are icons without
/// a `body`). Each is `<svg viewBox="left top w h">body</svg>` with the set's default size.
pub fn icons(set_json: &str) -> Result<Vec<IconSvg>, IconSetError> {
    let data: Value = serde_json::from_str(set_json).map_err(IconSetError::Json)?;
    let icons = data
        .get("icons")
        .and_then(Value::as_object)
        .ok_or(IconSetError::NoIcons)?;
    let (dw, dh) = (num(&data, "width", 16.0), num(&data, "height", 16.0));
    let mut out: Vec<IconSvg> = icons
        .iter()
        .filter_map(|(name, icon)| {
            let body = icon.get("body").and_then(Value::as_str)?;
            let (w, h) = (num(icon, "width", dw), num(icon, "height", dh));
            let (l, t) = (num(icon, "left", 0.0), num(icon, "top", 0.0));
            Some(IconSvg {
                name: name.clone(),
                svg: format!(
                    r#"<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" width="{w}" height="{h}" viewBox="{l} {t} {w} {h}">{body}</svg>"#
                ),
            })
        })
        .collect();
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

/// Renders an icon fitted and centred in a `size x size` square over white, as 8-bit RGB;
/// `Ok(None)` when nothing is drawn (all white).
pub fn render_rgb8(svg: &str, size: u32) -> Result<Option<Vec<u8>>, RenderError> {
    let tree = crate::svg::parse_usvg(svg)?;
    let mut pixmap = crate::svg::pixmap(size, size)?;
    pixmap.fill(tiny_skia::Color::WHITE);
    let s = tree.size();
    let k = size as f32 / s.width().max(s.height());
    let (dx, dy) = (
        (size as f32 - s.width() * k) / 2.0,
        (size as f32 - s.height() * k) / 2.0,
    );
    let t = tiny_skia::Transform::from_row(k, 0.0, 0.0, k, dx, dy);
    resvg::render(&tree, t, &mut pixmap.as_mut());
    let rgb: Vec<u8> = pixmap
        .data()
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    Ok(if rgb.iter().all(|&b| b == 255) {
        None
    } else {
        Some(rgb)
    })
}

/// [`render_rgb8`] as an opaque [`Image`] (a blank icon renders white).
pub fn render_image(svg: &str, size: u32) -> Result<Image, RenderError> {
    let rgb = render_rgb8(svg, size)?.unwrap_or_else(|| vec![255; (3 * size * size) as usize]);
    let mut im = Image::new(size, size);
    for (dst, px) in im.data.chunks_exact_mut(4).zip(rgb.chunks_exact(3)) {
        for (d, &v) in dst.iter_mut().zip(px) {
            *d = f32::from(v) / 255.0;
        }
        dst[3] = 1.0;
    }
    Ok(im)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SET: &str = r##"{"prefix":"t","width":32,"height":32,"icons":{
        "red-square":{"body":"<rect x=\"8\" y=\"8\" width=\"16\" height=\"16\" fill=\"#f00\"/>"},
        "blank":{"body":"<g/>"},
        "wide":{"body":"<rect width=\"64\" height=\"32\" fill=\"#00f\"/>","width":64}
    },"aliases":{"alias":{"parent":"red-square"}}}"##;

    #[test]
    fn icons_become_standalone_svgs_and_render_centred() {
        let icons = icons(SET).unwrap();
        let names: Vec<&str> = icons.iter().map(|i| i.name.as_str()).collect();
        assert_eq!(names, ["blank", "red-square", "wide"]);
        let red = render_image(&icons[1].svg, 32).unwrap();
        assert_eq!(red.pixel(16, 16), [1.0, 0.0, 0.0, 1.0]);
        assert_eq!(red.pixel(2, 2), [1.0, 1.0, 1.0, 1.0]);
        assert_eq!(render_rgb8(&icons[0].svg, 16).unwrap(), None);
        // a 2:1 icon is fitted to the width and centred vertically
        let wide = render_image(&icons[2].svg, 32).unwrap();
        assert_eq!(wide.pixel(16, 16), [0.0, 0.0, 1.0, 1.0]);
        assert_eq!(wide.pixel(16, 2), [1.0, 1.0, 1.0, 1.0]);
        assert!(super::icons("{}").is_err());
    }
}
