//! Texture paint → SVG: a texture ([`crate::scene::Texture`]) is written as a
//! `<pattern patternUnits="userSpaceOnUse">` one texture wide and high, its transform as the
//! `patternTransform`, holding one `<image>` with the texels re-encoded as a PNG `data:` URL
//! (straight alpha, 8 bits; `image-rendering="optimizeSpeed"` for nearest sampling,
//! `style="image-rendering:smooth"` for bilinear, nothing for the default bicubic). The shape
//! refers to it as `url(#gK)` like to a gradient. A pattern repeats where the texture pads: the
//! two differ only outside the image's rectangle, which an imported image's shape never covers.

use super::export::push_attr;
use super::export_paint::exact;
use crate::scene::{Texture, TextureFilter};
use base64::Engine;
use std::fmt::Write;

pub(super) fn push_texture(out: &mut String, t: &Texture, id: &str) {
    let (w, h) = (t.width.to_string(), t.height.to_string());
    out.push_str("<pattern");
    push_attr(out, "id", id);
    push_attr(out, "patternUnits", "userSpaceOnUse");
    push_attr(out, "width", &w);
    push_attr(out, "height", &h);
    let m: Vec<String> = t.transform.0.iter().map(|v| exact(*v)).collect();
    push_attr(out, "patternTransform", &format!("matrix({})", m.join(" ")));
    out.push_str(">\n<image");
    push_attr(out, "width", &w);
    push_attr(out, "height", &h);
    push_attr(out, "preserveAspectRatio", "none");
    match t.filter {
        TextureFilter::Nearest => push_attr(out, "image-rendering", "optimizeSpeed"),
        TextureFilter::Bilinear => push_attr(out, "style", super::profile::SMOOTH_STYLE),
        TextureFilter::Bicubic => {}
    }
    let _ = writeln!(out, " href=\"data:image/png;base64,{}\"/>", png_base64(t));
    out.push_str("</pattern>\n");
}

/// The texels as a base64 PNG (straight alpha).
fn png_base64(t: &Texture) -> String {
    let straight = t.straight_pixels();
    let mut png = Vec::new();
    let enc = image::codecs::png::PngEncoder::new(&mut png);
    use image::ImageEncoder;
    // Encoding into memory fails only on a size mismatch, which the texture's invariants rule out.
    if enc
        .write_image(
            &straight,
            t.width,
            t.height,
            image::ExtendedColorType::Rgba8,
        )
        .is_err()
    {
        png.clear();
    }
    base64::engine::general_purpose::STANDARD.encode(png)
}
