//! The SVG writer ([`to_svg`], [`with_metadata`]); the format is described in the docs of
//! [`crate::svg`].
//!
//! Coordinates are rounded once to integers in units of `10^-precision` and every later decision
//! (relative or absolute, `H`/`V`, `S`, closing by `Z`) works on those integers, so relative
//! coordinates are exact: a reader that sums them gets the same decimals as the absolute form,
//! and rounding errors never accumulate along a path.

use super::path_data::push_path_data;
use crate::scene::{Rgba, Scene, Shape};
use std::fmt::Write as _;

/// Export options.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SvgOptions {
    /// Decimal places for coordinates and stroke widths (0..=6; larger values are capped).
    /// Opacities get `max(3, precision)` decimals.
    pub precision: u8,
    /// Wraps runs of two or more consecutive shapes with the same fill in one
    /// `<g fill="…">` (and the run's common `fill-opacity`, if any), instead of repeating it.
    pub group_by_color: bool,
    /// Gives every path the id `p<k>` (`k` = the shape's index in the scene + 1, so ids follow
    /// paint order and stay the same for the same scene) and every colour group `c<k>`
    /// (`k` = 1, 2, … in document order).
    pub ids: bool,
    /// Wraps runs of consecutive shapes added by one LIVE stage ([`Shape::stage`]) in one `<g>`
    /// with the id `s<k>` (`k` = the stage; a later run of the same stage `s<k>-<n>`, `n` = 2,
    /// 3, …); shapes without a stage stay outside any group.
    pub group_by_stage: bool,
    /// User units per pixel (`1..=`[`MAX_UNITS_PER_PX`]; 0 counts as 1): with `k > 1` the
    /// document keeps its `width` and `height` in pixels but its `viewBox` is `k` times larger,
    /// and every coordinate and stroke width is written `k` times larger. With `precision` 0
    /// this puts coordinates on a grid of `1/k` px written as integers: no decimal point, and
    /// grids between the powers of ten (1/2, 1/4, 1/20 px …) that decimals cannot express.
    pub units_per_px: u32,
}

impl Default for SvgOptions {
    fn default() -> Self {
        SvgOptions {
            precision: 2,
            group_by_color: false,
            ids: false,
            group_by_stage: false,
            units_per_px: 1,
        }
    }
}

/// Largest [`SvgOptions::units_per_px`] written (larger values are capped).
pub const MAX_UNITS_PER_PX: u32 = 1000;

/// Largest number of decimals written.
pub const MAX_PRECISION: u8 = 6;

/// Fewest decimals an opacity gets (1/1000 is finer than an 8-bit alpha step).
const OPACITY_DECIMALS: usize = 3;

/// Largest magnitude (in units of `10^-precision`) written through the integer path; larger or
/// non-finite values are written as they are (see [`push_float`]).
const MAX_UNITS: f64 = 1e15;

/// `v` in units of `10^-p` (as `scale = 10^p`), rounded, if finite and not huge.
pub(super) fn to_units(v: f32, scale: f64) -> Option<i64> {
    let x = (v as f64 * scale).round();
    (x.is_finite() && x.abs() <= MAX_UNITS).then_some(x as i64)
}

/// `u * 10^-p` in its shortest form: no trailing zeros, no `0` before the point (`.5`, `-.5`),
/// no `-0`.
pub(super) fn push_fixed(out: &mut String, u: i64, p: usize) {
    if u < 0 {
        out.push('-');
    }
    let a = u.unsigned_abs();
    let s = 10u64.pow(p as u32);
    let (int, mut frac) = (a / s, a % s);
    if frac == 0 {
        let _ = write!(out, "{int}");
        return;
    }
    if int != 0 {
        let _ = write!(out, "{int}");
    }
    let mut digits = p;
    while frac % 10 == 0 {
        frac /= 10;
        digits -= 1;
    }
    let _ = write!(out, ".{frac:0digits$}");
}

/// A value the integer path cannot hold (non-finite or huge), written as Rust prints it, with `p`
/// decimals when finite: invalid scenes are written as they are, never silently changed.
fn push_float(out: &mut String, v: f32, p: usize) {
    if v.is_finite() {
        let _ = write!(out, "{v:.p$}");
    } else {
        let _ = write!(out, "{v}");
    }
}

/// `v` with `p` decimals in the shortest form.
pub(super) fn num(v: f32, p: usize) -> String {
    let mut s = String::new();
    match to_units(v, 10f64.powi(p as i32)) {
        Some(u) => push_fixed(&mut s, u, p),
        None => push_float(&mut s, v, p),
    }
    s
}

/// A colour channel as the 8 bits every SVG renderer keeps.
fn byte(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// `#rgb` when every channel's two hex digits are equal, else `#rrggbb`.
pub(super) fn hex(c: Rgba) -> String {
    let b = [byte(c.r), byte(c.g), byte(c.b)];
    if b.iter().all(|v| v >> 4 == v & 15) {
        format!("#{:x}{:x}{:x}", b[0] & 15, b[1] & 15, b[2] & 15)
    } else {
        format!("#{:02x}{:02x}{:02x}", b[0], b[1], b[2])
    }
}

pub(super) fn opacity_decimals(p: usize) -> usize {
    p.max(OPACITY_DECIMALS)
}

/// The colour a reader gets back from what [`to_svg`] writes for `c` at `precision` decimals:
/// 8-bit RGB and the opacity with `max(3, precision)` decimals.
pub fn written_color(c: Rgba, precision: u8) -> Rgba {
    let p = opacity_decimals(precision.min(MAX_PRECISION) as usize);
    let s = 10f64.powi(p as i32);
    let a = ((c.a.clamp(0.0, 1.0) as f64 * s).round() / s) as f32;
    Rgba::new(
        byte(c.r) as f32 / 255.0,
        byte(c.g) as f32 / 255.0,
        byte(c.b) as f32 / 255.0,
        a,
    )
}

/// How a shape is painted, as attribute values.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Paint {
    /// `none` or a colour.
    fill: String,
    /// `None` when opaque (the default).
    fill_opacity: Option<String>,
    stroke: Option<StrokePaint>,
    /// Whether a drawn fill is even-odd (`fill-rule="evenodd"`).
    even_odd: bool,
}

#[derive(Clone, Debug, PartialEq)]
struct StrokePaint {
    color: String,
    width: String,
    opacity: Option<String>,
    /// The cap, join and miter limit attributes (` stroke-linecap="round" …`).
    caps: String,
}

/// The attributes of `st`'s caps and joins that differ from SVG's defaults (butt caps, miter
/// joins, miter limit 4).
fn caps_attrs(st: &crate::scene::Stroke) -> String {
    use crate::scene::{LineCap, LineJoin};
    let mut out = String::new();
    match st.cap {
        LineCap::Round => push_attr(&mut out, "stroke-linecap", "round"),
        LineCap::Square => push_attr(&mut out, "stroke-linecap", "square"),
        LineCap::Butt => {}
    }
    match st.join {
        LineJoin::Round => push_attr(&mut out, "stroke-linejoin", "round"),
        LineJoin::Bevel => push_attr(&mut out, "stroke-linejoin", "bevel"),
        LineJoin::Miter if st.miter_limit != crate::scene::Stroke::DEFAULT_MITER_LIMIT => {
            push_attr(&mut out, "stroke-miterlimit", &num(st.miter_limit, 3));
        }
        LineJoin::Miter => {}
    }
    out
}

impl Paint {
    /// The shape's paint attributes; `ids` names its gradients (`url(#id)` replaces the flat
    /// stand-in colour, whose opacity the gradient's stops already carry).
    pub(super) fn of(sh: &Shape, p: usize, ids: &(Option<String>, Option<String>)) -> Paint {
        let op = |a: f32| {
            let s = num(a.clamp(0.0, 1.0), opacity_decimals(p));
            match s.as_str() {
                "1" => Some(None),
                "0" => None,
                _ => Some(Some(s)),
            }
        };
        let (fill, fill_opacity) = match sh.fill {
            Some(_) if sh.is_closed() && ids.0.is_some() => (
                format!("url(#{})", ids.0.as_deref().unwrap_or_default()),
                None,
            ),
            Some(f) if sh.is_closed() => match op(f.a) {
                Some(o) => (hex(f), o),
                None => ("none".to_string(), None),
            },
            _ => ("none".to_string(), None),
        };
        let stroke = sh.stroke.and_then(|st| {
            let width = num(st.width, p);
            let visible = st.width > 0.0 && width != "0";
            let (color, opacity) = match &ids.1 {
                Some(id) => (format!("url(#{id})"), None),
                None => (hex(st.color), op(st.color.a)?),
            };
            visible.then(|| StrokePaint {
                color,
                width,
                opacity,
                caps: caps_attrs(&st),
            })
        });
        Paint {
            even_odd: fill != "none" && !sh.fill_rule.is_nonzero(),
            fill,
            fill_opacity,
            stroke,
        }
    }

    pub(super) fn visible(&self) -> bool {
        self.fill != "none" || self.stroke.is_some()
    }
}

/// What the enclosing elements already set, so a path leaves those attributes out.
#[derive(Clone, Debug)]
pub(super) struct Inherited {
    fill: String,
    fill_opacity: Option<String>,
    stroke: Option<String>,
    stroke_width: Option<String>,
    stroke_opacity: Option<String>,
    /// The cap and join attributes an enclosing group set.
    caps: Option<String>,
}

impl Inherited {
    pub(super) fn root() -> Self {
        Inherited {
            fill: "#000".into(),
            fill_opacity: None,
            stroke: None,
            stroke_width: None,
            stroke_opacity: None,
            caps: None,
        }
    }
}

pub(super) fn push_attr(out: &mut String, name: &str, value: &str) {
    let _ = write!(out, r#" {name}="{value}""#);
}

pub(super) fn push_paint(out: &mut String, paint: &Paint, ctx: &Inherited) {
    if paint.fill != ctx.fill {
        push_attr(out, "fill", &paint.fill);
    }
    if paint.fill != "none"
        && paint.fill_opacity != ctx.fill_opacity
        && let Some(o) = &paint.fill_opacity
    {
        push_attr(out, "fill-opacity", o);
    }
    if paint.even_odd {
        push_attr(out, "fill-rule", "evenodd");
    }
    if let Some(st) = &paint.stroke {
        if ctx.stroke.as_ref() != Some(&st.color) {
            push_attr(out, "stroke", &st.color);
        }
        if ctx.stroke_width.as_ref() != Some(&st.width) {
            push_attr(out, "stroke-width", &st.width);
        }
        if st.opacity != ctx.stroke_opacity
            && let Some(o) = &st.opacity
        {
            push_attr(out, "stroke-opacity", o);
        }
        if ctx.caps.as_ref() != Some(&st.caps) {
            out.push_str(&st.caps);
        }
    }
}

/// The value every item of `items` has, if there are any and they agree.
fn common<T: PartialEq + Clone>(mut items: impl Iterator<Item = T>) -> Option<T> {
    let first = items.next()?;
    items.all(|v| v == first).then_some(first)
}

/// Writes `scene` as a standalone SVG document (see the docs of [`crate::svg`]). Never fails
/// for a scene that passes [`Scene::validate`]; invalid values are written as they are.
pub fn to_svg(scene: &Scene, opts: &SvgOptions) -> String {
    let k = opts.units_per_px.clamp(1, MAX_UNITS_PER_PX);
    let scaled;
    let size = (scene.width, scene.height);
    let scene = if k > 1 {
        scaled = scene.scaled_by(k);
        &scaled
    } else {
        scene
    };
    let mut w = Writer {
        out: String::with_capacity(128 + 96 * scene.shapes.len()),
        scene,
        size,
        opts,
        p: opts.precision.min(MAX_PRECISION) as usize,
        groups: 0,
        stage_runs: std::collections::BTreeMap::new(),
    };
    w.header();
    if !scene.groups.is_empty() {
        return super::export_groups::layered(w);
    }
    let mut defs = super::export_paint::PaintDefs::default();
    let ids: Vec<_> = scene.shapes.iter().map(|sh| defs.of_shape(sh)).collect();
    if !defs.text.is_empty() {
        w.out.push_str("<defs>\n");
        w.out.push_str(&defs.text);
        w.out.push_str("</defs>\n");
    }
    let items: Vec<(usize, Paint)> = scene
        .shapes
        .iter()
        .zip(&ids)
        .enumerate()
        .map(|(i, (sh, id))| (i, Paint::of(sh, w.p, id)))
        .filter(|(_, paint)| paint.visible())
        .collect();
    let mut ctx = Inherited::root();
    let outer = w.stroke_group(&items, &mut ctx);
    let mut i = 0;
    while i < items.len() {
        i = if opts.group_by_stage {
            w.stage_run(&items, i, &ctx)
        } else {
            w.fill_run(&items, i, &ctx)
        };
    }
    if outer {
        w.out.push_str("</g>\n");
    }
    w.out.push_str("</svg>\n");
    w.out
}

/// One scene being written.
pub(super) struct Writer<'a> {
    pub(super) out: String,
    /// The scene in user units (`units_per_px` times the pixel scene).
    pub(super) scene: &'a Scene,
    /// The document's `width` and `height` in pixels.
    size: (u32, u32),
    opts: &'a SvgOptions,
    /// Decimals of coordinates.
    pub(super) p: usize,
    /// Colour groups written so far (their ids count up).
    groups: usize,
    /// Stage groups written so far, per stage.
    stage_runs: std::collections::BTreeMap<u16, usize>,
}

impl Writer<'_> {
    /// The `<svg>` element and the background rectangle (when the background shows).
    pub(super) fn header(&mut self) {
        let (w, h) = (self.scene.width, self.scene.height);
        let (pw, ph) = self.size;
        let out = &mut self.out;
        let _ = write!(
            out,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{pw}" height="{ph}" viewBox="0 0 {w} {h}">"#
        );
        out.push('\n');
        let background = self.scene.background;
        if background.a > 0.0 {
            let _ = write!(out, r#"<rect width="{w}" height="{h}""#);
            let c = hex(background);
            if c != "#000" {
                push_attr(out, "fill", &c);
            }
            let o = num(background.a.clamp(0.0, 1.0), opacity_decimals(self.p));
            if o != "1" {
                push_attr(out, "fill-opacity", &o);
            }
            out.push_str("/>\n");
        }
    }

    /// Opens one outer group with the stroke attributes shared by all stroked paths, when two
    /// or more are stroked (their caps and joins are usually round, so two stroked paths
    /// already pay for it); `ctx` learns what it sets. Returns whether it opened one.
    fn stroke_group(&mut self, items: &[(usize, Paint)], ctx: &mut Inherited) -> bool {
        let stroked: Vec<&StrokePaint> = items
            .iter()
            .filter_map(|(_, q)| q.stroke.as_ref())
            .collect();
        if stroked.len() < 2 {
            return false;
        }
        let out = &mut self.out;
        let all_stroked = stroked.len() == items.len();
        out.push_str("<g");
        if let Some(f) = common(items.iter().map(|(_, q)| &q.fill))
            && f == "none"
        {
            ctx.fill = f.clone();
            push_attr(out, "fill", f);
        }
        if all_stroked && let Some(c) = common(stroked.iter().map(|s| &s.color)) {
            push_attr(out, "stroke", c);
            ctx.stroke = Some(c.clone());
        }
        if let Some(wd) = common(stroked.iter().map(|s| &s.width)) {
            push_attr(out, "stroke-width", wd);
            ctx.stroke_width = Some(wd.clone());
        }
        if all_stroked && let Some(Some(o)) = common(stroked.iter().map(|s| &s.opacity)) {
            push_attr(out, "stroke-opacity", o);
            ctx.stroke_opacity = Some(o.clone());
        }
        if let Some(c) = common(stroked.iter().map(|s| &s.caps)) {
            out.push_str(c);
            ctx.caps = Some(c.clone());
        }
        out.push_str(">\n");
        true
    }

    /// The paths from `items[i]` on that one LIVE stage added, in one `<g id="s<k>">` (see
    /// [`SvgOptions::group_by_stage`]); paths without a stage one by one. Returns where the
    /// next run starts.
    fn stage_run(&mut self, items: &[(usize, Paint)], i: usize, ctx: &Inherited) -> usize {
        let stage_of = |k: usize| self.scene.shapes[items[k].0].stage;
        let stage = stage_of(i);
        let mut j = i + 1;
        while j < items.len() && stage_of(j) == stage {
            j += 1;
        }
        let Some(s) = stage else {
            return self.fill_run(items, i, ctx);
        };
        let n = self.stage_runs.entry(s).or_insert(0);
        *n += 1;
        let id = match *n {
            1 => format!("s{s}"),
            n => format!("s{s}-{n}"),
        };
        self.out.push_str("<g");
        push_attr(&mut self.out, "id", &id);
        self.out.push_str(">\n");
        let run = &items[i..j];
        let mut k = 0;
        while k < run.len() {
            k = self.fill_run(run, k, ctx);
        }
        self.out.push_str("</g>\n");
        j
    }

    /// The paths from `items[i]` on: a run of two or more with one fill in a colour group
    /// (when grouping by colour and the fill is not inherited already), else the one path.
    /// Returns where the next run starts.
    fn fill_run(&mut self, items: &[(usize, Paint)], i: usize, ctx: &Inherited) -> usize {
        let fill = &items[i].1.fill;
        let mut j = i + 1;
        while j < items.len() && &items[j].1.fill == fill {
            j += 1;
        }
        let run = &items[i..j];
        let grouped = self.opts.group_by_color && run.len() >= 2 && *fill != ctx.fill;
        let mut inner = ctx.clone();
        if grouped {
            self.groups += 1;
            let out = &mut self.out;
            out.push_str("<g");
            if self.opts.ids {
                push_attr(out, "id", &format!("c{}", self.groups));
            }
            push_attr(out, "fill", fill);
            inner.fill = fill.clone();
            if *fill != "none"
                && let Some(Some(o)) = common(run.iter().map(|(_, q)| &q.fill_opacity))
            {
                push_attr(out, "fill-opacity", o);
                inner.fill_opacity = Some(o.clone());
            }
            out.push_str(">\n");
        }
        let run_end = if grouped { j } else { i + 1 };
        for (index, paint) in &items[i..run_end] {
            let out = &mut self.out;
            out.push_str("<path");
            if self.opts.ids {
                push_attr(out, "id", &format!("p{}", index + 1));
            }
            out.push_str(r#" d=""#);
            push_path_data(out, &self.scene.shapes[*index], self.p);
            out.push('"');
            push_paint(out, paint, &inner);
            out.push_str("/>\n");
        }
        if grouped {
            self.out.push_str("</g>\n");
        }
        run_end
    }
}

/// `svg` (a document [`to_svg`] wrote) with a `<metadata>` element holding `text` (XML-escaped;
/// control characters dropped) right after the opening `<svg ...>` tag. A document without an
/// opening tag is returned unchanged.
pub fn with_metadata(svg: &str, text: &str) -> String {
    let Some(end) = svg
        .find("<svg")
        .and_then(|i| svg[i..].find('>').map(|j| i + j + 1))
    else {
        return svg.to_string();
    };
    let mut esc = String::with_capacity(text.len() + 16);
    for ch in text.chars() {
        match ch {
            '&' => esc.push_str("&amp;"),
            '<' => esc.push_str("&lt;"),
            '>' => esc.push_str("&gt;"),
            '"' => esc.push_str("&quot;"),
            c if c.is_control() => {}
            c => esc.push(c),
        }
    }
    format!("{}\n<metadata>{esc}</metadata>{}", &svg[..end], &svg[end..])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_short() {
        let f = |u: i64, p: usize| {
            let mut s = String::new();
            push_fixed(&mut s, u, p);
            s
        };
        assert_eq!(f(0, 2), "0");
        assert_eq!(f(50, 2), ".5");
        assert_eq!(f(-50, 2), "-.5");
        assert_eq!(f(1205, 2), "12.05");
        assert_eq!(f(-1200, 2), "-12");
        assert_eq!(f(7, 3), ".007");
        assert_eq!(f(42, 0), "42");
        assert_eq!(num(-0.001, 2), "0");
        assert_eq!(num(f32::NAN, 2), "NaN");
        assert_eq!(hex(Rgba::WHITE), "#fff");
        assert_eq!(hex(Rgba::new(1.0, 0.0, 0.2, 1.0)), "#f03");
        assert_eq!(hex(Rgba::new(1.0, 0.0, 0.21, 1.0)), "#ff0036");
    }
}
