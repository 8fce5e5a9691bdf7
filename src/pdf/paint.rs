//! The paints of a PDF page: gradients as shading patterns, textures as tiling patterns.

use super::{PT_PER_PX, nums, stream_object};
use crate::scene::{
    Affine, Gradient, GradientGeometry, MaskKind, Point, Rgba, Shape, Spread, Texture,
    TextureFilter,
};

/// The range of a gradient's parameter `t` over the shape (its control points bound its
/// outline; a stroke's half width added), whole periods outward: `[0, 1]` for `pad` (but for a
/// linear one that [`steps_at_an_end`]); for a linear gradient the projections onto its axis;
/// for a radial one `[0, n]`, the first circle that holds every point.
pub(super) fn t_range(g: &Gradient, shape: &Shape) -> [f32; 2] {
    let linear = matches!(g.geometry, GradientGeometry::Linear { .. });
    if g.spread == Spread::Pad && !(linear && steps_at_an_end(g)) {
        return [0.0, 1.0];
    }
    // Canvas → gradient space (a singular map gives non-finite `t`s, which are passed over).
    let inv = Affine(g.transform.inverse_f64().map(|v| v as f32));
    let pad = shape.stroke.map_or(0.0, |s| s.width / 2.0);
    let t_at: Box<dyn Fn(Point) -> f32> = match g.geometry {
        GradientGeometry::Linear { x1, y1, x2, y2 } => {
            let (dx, dy) = (x2 - x1, y2 - y1);
            let len2 = dx * dx + dy * dy;
            Box::new(move |q: Point| ((q.x - x1) * dx + (q.y - y1) * dy) / len2)
        }
        GradientGeometry::Radial { .. } => {
            let [[fx, fy, fr], [cx, cy, r]] = g.geometry.ends();
            // The circle at `t` (centre f + t (c − f), radius fr + t (r − fr)) holds a point at
            // distance `l` from f once fr + t (r − fr) ≥ l + t |c − f|.
            let grow = (r - fr) - (cx - fx).hypot(cy - fy);
            Box::new(move |q: Point| ((q.x - fx).hypot(q.y - fy) - fr) / grow)
        }
    };
    let (mut lo, mut hi) = (0.0f32, 1.0f32);
    for p in &shape.points {
        for (ox, oy) in [(-pad, -pad), (pad, -pad), (-pad, pad), (pad, pad)] {
            let t = t_at(inv.apply(Point::new(p.x + ox, p.y + oy)));
            if t.is_finite() {
                (lo, hi) = (lo.min(t), hi.max(t));
            }
        }
    }
    if !linear {
        lo = 0.0;
    }
    // At most 256 periods: past that the stripes are finer than any page shows.
    let lo = lo.floor().max(hi.ceil() - 256.0);
    [lo, hi.ceil().min(lo + 256.0)]
}

/// Whether the first two stops (or the last two) stand at the end offset with different
/// colours: SVG pads with the outer stop's colour, a shading's extension with the inner one's,
/// so such a `pad` gradient spans the shape's range with the padding drawn as constant pieces.
fn steps_at_an_end(g: &Gradient) -> bool {
    let s = &g.stops;
    let n = s.len();
    // The import moves the second of two equal offsets up by a hair (as usvg does).
    const HAIR: f32 = 1e-4;
    n >= 2
        && ((s[1].offset <= HAIR && s[0].color != s[1].color)
            || (s[n - 2].offset >= 1.0 - HAIR && s[n - 2].color != s[n - 1].color))
}

/// `[a b c d e f]`: gradient or texel space → canvas (`m`), and on a page `flip` points high
/// (a pattern drawn in the page's own content) on to page points, y up; a pattern drawn inside
/// a form stays in canvas pixels, the form's space.
fn pattern_matrix(m: &Affine, flip: Option<f32>) -> String {
    let [a, b, c, d, e, f] = m.0;
    let Some(page_h) = flip else {
        return format!("[{}]", nums([a, b, c, d, e, f]));
    };
    let k = PT_PER_PX;
    format!(
        "[{}]",
        nums([k * a, -k * b, k * c, -k * d, k * e, page_h - k * f])
    )
}

/// What a colour is drawn as.
#[derive(Clone, Copy, PartialEq)]
pub(super) enum Channel {
    /// Itself.
    Colour,
    /// Its alpha, as a grey (a soft mask of stop opacities).
    Alpha,
    /// Its luminance by SVG's weights, as a grey, which PDF's luminosity (its own weights) reads
    /// back unchanged: what a luminance mask's content is drawn in.
    Luminance,
}

impl Channel {
    pub(super) fn map(self, c: Rgba) -> Rgba {
        let grey = |v: f32| Rgba::new(v, v, v, c.a);
        match self {
            Channel::Colour => c,
            Channel::Alpha => grey(c.a),
            Channel::Luminance => {
                let [wr, wg, wb] = MaskKind::LUMINANCE_WEIGHTS.map(|w| w as f32);
                grey(wr * c.r + wg * c.g + wb * c.b)
            }
        }
    }

    /// A straight RGBA texel's colour as this channel draws it.
    pub(super) fn map_texel(self, p: [u8; 4]) -> [u8; 3] {
        if self == Channel::Colour {
            return [p[0], p[1], p[2]];
        }
        let c = Rgba::new(
            p[0] as f32 / 255.0,
            p[1] as f32 / 255.0,
            p[2] as f32 / 255.0,
            p[3] as f32 / 255.0,
        );
        let m = self.map(c);
        [m.r, m.g, m.b].map(|v| (v * 255.0).round().clamp(0.0, 255.0) as u8)
    }
}

/// The stops of `g` as a function of `t` over `range` (whole periods of `repeat` or `reflect`,
/// else `[0, 1]`): a stitching function of linear pieces between stops, of their colours as
/// `channel` draws them (opaque: the alpha is the pattern's graphics state).
fn stop_function(g: &Gradient, range: [f32; 2], channel: Channel) -> String {
    // Stops covering [0, 1].
    let mut stops: Vec<(f32, Rgba)> = g
        .stops
        .iter()
        .map(|s| (s.offset.clamp(0.0, 1.0), channel.map(s.color)))
        .collect();
    if stops.is_empty() {
        stops.push((0.0, Rgba::BLACK));
    }
    if stops[0].0 > 0.0 {
        stops.insert(0, (0.0, stops[0].1));
    }
    if let Some(&(o, c)) = stops.last()
        && o < 1.0
    {
        stops.push((1.0, c));
    }
    let rgb = |c: Rgba| nums([c.r, c.g, c.b]);
    let piece = |a: Rgba, b: Rgba| {
        format!(
            "<< /FunctionType 2 /Domain [0 1] /C0 [{}] /C1 [{}] /N 1 >>",
            rgb(a),
            rgb(b)
        )
    };
    // One period: a piece per pair of stops (a pair at one offset is a hard step).
    let mut funcs = Vec::new();
    let mut bounds = Vec::new();
    for w in stops.windows(2) {
        funcs.push(piece(w[0].1, w[1].1));
        bounds.push(w[1].0);
    }
    bounds.pop();
    let period = |flip: bool, lo: f32| {
        let (mut f, mut b) = (funcs.clone(), bounds.clone());
        let mut encode = vec!["0 1"; f.len()];
        if flip {
            f.reverse();
            b = b.iter().rev().map(|v| 1.0 - v).collect();
            encode = vec!["1 0"; f.len()];
        }
        format!(
            "<< /FunctionType 3 /Domain [{}] /Functions [{}] /Bounds [{}] /Encode [{}] >>",
            nums([lo, lo + 1.0]),
            f.join(" "),
            nums(b.iter().map(|v| lo + v)),
            encode.join(" ")
        )
    };
    let [lo, hi] = range;
    if hi - lo <= 1.0 && lo == 0.0 {
        return period(false, 0.0);
    }
    if g.spread == Spread::Pad {
        // The stops over [0, 1], the outer stops' colours before and after.
        let (first, last) = (stops[0].1, stops[stops.len() - 1].1);
        let mut parts = vec![period(false, 0.0)];
        let mut bounds = Vec::new();
        if lo < 0.0 {
            parts.insert(0, piece(first, first));
            bounds.push(0.0);
        }
        if hi > 1.0 {
            parts.push(piece(last, last));
            bounds.push(1.0);
        }
        return format!(
            "<< /FunctionType 3 /Domain [{}] /Functions [{}] /Bounds [{}] /Encode [{}] >>",
            nums([lo, hi]),
            parts.join(" "),
            nums(bounds),
            vec!["0 1"; parts.len()].join(" ")
        );
    }
    // Whole periods: each its own stitched function, mirrored on odd ones for `reflect`.
    let n = (hi - lo).round().max(1.0) as i64;
    let starts: Vec<f32> = (0..n).map(|k| lo + k as f32).collect();
    let parts: Vec<String> = starts
        .iter()
        .map(|&start| {
            let odd = (start as i64).rem_euclid(2) == 1;
            period(g.spread == Spread::Reflect && odd, start)
        })
        .collect();
    format!(
        "<< /FunctionType 3 /Domain [{}] /Functions [{}] /Bounds [{}] /Encode [{}] >>",
        nums([lo, hi]),
        parts.join(" "),
        nums(starts[1..].iter().copied()),
        nums(starts.iter().flat_map(|&s| [s, s + 1.0]))
    )
}

/// The shading pattern of gradient `g` over the parameter range `range` (`flip`: see
/// [`pattern_matrix`]), its colours as `channel` draws them ([`stop_function`]).
pub(super) fn gradient_object(
    g: &Gradient,
    range: [f32; 2],
    flip: Option<f32>,
    channel: Channel,
) -> Vec<u8> {
    let [lo, hi] = range;
    let [start, end] = g.geometry.ends();
    let at = |t: f32| -> [f32; 3] { std::array::from_fn(|i| start[i] + t * (end[i] - start[i])) };
    let (kind, coords) = match g.geometry {
        // The axis at the range's ends: t = lo and t = hi.
        GradientGeometry::Linear { .. } => {
            (2, nums(at(lo)[..2].iter().chain(&at(hi)[..2]).copied()))
        }
        // From the focal circle (t = 0) to the circle at t = hi (the end circle at t = 1).
        GradientGeometry::Radial { .. } => (3, nums(at(0.0).into_iter().chain(at(hi)))),
    };
    format!(
        "<< /Type /Pattern /PatternType 2 /Matrix {} /Shading << /ShadingType {kind} \
         /ColorSpace /DeviceRGB /Coords [{coords}] /Domain [{}] /Function {} \
         /Extend [true true] >> >>",
        pattern_matrix(&g.transform, flip),
        nums([lo, hi]),
        stop_function(g, range, channel)
    )
    .into_bytes()
}

/// `data` deflated (zlib, as `/FlateDecode` reads it).
fn deflate(data: &[u8]) -> Vec<u8> {
    use std::io::Write as _;
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    // Writing into memory cannot fail.
    let _ = z.write_all(data);
    z.finish().unwrap_or_default()
}

/// The three objects that draw texture `t` as a tiling pattern (`flip`: see [`pattern_matrix`]):
/// the texels' colours (straight RGB, as `channel` draws them), their alpha (the soft mask,
/// object `first + 1`), and the pattern (cell = the texture, placed by its transform and the
/// page's flip); `first` is the colour image's object number.
pub(super) fn texture_objects(
    t: &Texture,
    first: usize,
    flip: Option<f32>,
    channel: Channel,
) -> [Vec<u8>; 3] {
    let (w, h) = (t.width, t.height);
    let straight = t.straight_pixels();
    let rgb: Vec<u8> = straight
        .chunks_exact(4)
        .flat_map(|p| channel.map_texel([p[0], p[1], p[2], p[3]]))
        .collect();
    let alpha: Vec<u8> = straight.chunks_exact(4).map(|p| p[3]).collect();
    let interpolate = t.filter != TextureFilter::Nearest;
    let image = |space: &str, extra: &str, data: &[u8]| {
        stream_object(
            &format!(
                "/Type /XObject /Subtype /Image /Width {w} /Height {h} /ColorSpace {space} \
                 /BitsPerComponent 8 /Interpolate {interpolate} /Filter /FlateDecode{extra}"
            ),
            &deflate(data),
        )
    };
    let color = image("/DeviceRGB", &format!(" /SMask {} 0 R", first + 1), &rgb);
    let mask = image("/DeviceGray", "", &alpha);
    let matrix = pattern_matrix(&t.transform, flip);
    // The image's unit square onto the cell, its first row at texel row 0.
    let cell = format!("q {w} 0 0 -{h} 0 {h} cm /I Do Q");
    let pattern = stream_object(
        &format!(
            "/Type /Pattern /PatternType 1 /PaintType 1 /TilingType 1 /BBox [0 0 {w} {h}] \
             /XStep {w} /YStep {h} /Matrix {matrix} /Resources << /XObject << /I {first} 0 R >> >>"
        ),
        cell.as_bytes(),
    );
    [color, mask, pattern]
}
