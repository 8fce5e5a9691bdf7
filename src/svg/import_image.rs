//! `<image>` → scene: a raster image becomes its rectangle filled with a
//! [`crate::scene::Texture`]; an SVG image becomes its content, imported by the same walk, in a
//! group clipped to the image's viewport. usvg has already placed the image (x, y, width,
//! height, the intrinsic size, `preserveAspectRatio` with a clip for `slice`); `images` decided
//! where it may come from and bounded its size.

use super::images::Images;
use super::walk::{Mode, Walk, rect_shape};
use crate::scene::{Affine, Clip, Content, Gradients, Group, Texture, TextureEdge, TextureFilter};
use resvg::usvg;
use usvg::{ImageKind, ImageRendering, Transform};

/// Adds what `img` draws in user space `ts` to `out` (nothing when it does not decode: a
/// warning says so).
pub(super) fn image(
    walk: &mut Walk,
    images: &Images,
    img: &usvg::Image,
    ts: Transform,
    out: &mut Content,
) {
    if !img.is_visible() {
        return;
    }
    let size = img.size();
    let Some(rect) = usvg::NonZeroRect::from_xywh(0.0, 0.0, size.width(), size.height()) else {
        return;
    };
    let Some(mut shape) = rect_shape(rect, ts) else {
        return;
    };
    if let ImageKind::SVG(tree) = img.kind() {
        let start = out.shapes.len();
        let gi = out.groups.len();
        out.groups.push(Group::new(start..start, 1.0));
        walk.group(tree.root(), ts, Mode::Draw, out);
        let end = out.shapes.len();
        if end == start {
            out.groups.truncate(gi);
            return;
        }
        let mut g = Group::new(start..end, 1.0);
        g.clip = Some(Box::new(Clip {
            content: Content {
                shapes: vec![shape],
                groups: Vec::new(),
            },
            clip: None,
        }));
        out.groups[gi] = g;
        return;
    }
    let (w, h, pixels) = match images.decode(img.kind()) {
        Ok(d) => d,
        Err(e) => {
            walk.warn(format!("{} ignored: cannot decode: {e}", name(img)));
            return;
        }
    };
    let texel = Affine([
        size.width() / w as f32,
        0.0,
        0.0,
        size.height() / h as f32,
        0.0,
        0.0,
    ]);
    let user = Affine([ts.sx, ts.ky, ts.kx, ts.sy, ts.tx, ts.ty]);
    let texture = Texture {
        width: w,
        height: h,
        pixels,
        transform: user.then_after(&texel),
        edge: TextureEdge::Pad,
        filter: match img.rendering_mode() {
            ImageRendering::OptimizeQuality | ImageRendering::HighQuality => TextureFilter::Bicubic,
            ImageRendering::Smooth => TextureFilter::Bilinear,
            ImageRendering::OptimizeSpeed
            | ImageRendering::CrispEdges
            | ImageRendering::Pixelated => TextureFilter::Nearest,
        },
    };
    if let Err(e) = texture.validate() {
        walk.warn(format!("{} ignored: {e}", name(img)));
        return;
    }
    shape.fill = Some(texture.mean_color());
    shape.gradients = Some(Box::new(Gradients {
        fill: None,
        stroke: None,
        texture: Some(Box::new(texture)),
    }));
    out.shapes.push(shape);
}

fn name(img: &usvg::Image) -> String {
    match img.id() {
        "" => "an <image>".into(),
        id => format!("<image> #{id}"),
    }
}
