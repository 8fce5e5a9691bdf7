//! The walk over usvg's tree: groups become scene [`Group`]s (opacity, clip, mask) where they
//! need a layer, paths become shapes (see `import`), and what cannot be drawn is warned about.

use super::images::Images;
use super::import::{clip_path_shape, clip_shape, path_shapes};
use crate::scene::{BlendMode, Clip, Content, Group, Mask, MaskKind, Shape};
use resvg::usvg;
use std::sync::Arc;
use usvg::Transform;

/// Most warnings one import reports; the rest are counted in a last one.
pub(super) const MAX_WARNINGS: usize = 16;

/// What a walk collects: drawn content, or the geometry of a clip path.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Mode {
    Draw,
    /// A clip path's children: fills only (by their `clip-rule`), no opacity or mask.
    Clip,
}

/// What could not be drawn, and the canvas size (a mask region covering it is dropped).
pub(super) struct Walk {
    warnings: Vec<String>,
    more_warnings: usize,
    canvas: (f32, f32),
    /// Where this import's images come from (see `images`).
    images: Arc<Images>,
}

impl Walk {
    pub(super) fn new(canvas: (f32, f32), images: Arc<Images>) -> Self {
        Walk {
            warnings: Vec::new(),
            more_warnings: 0,
            canvas,
            images,
        }
    }

    pub(super) fn warn(&mut self, w: String) {
        if self.warnings.contains(&w) {
            return;
        }
        if self.warnings.len() < MAX_WARNINGS {
            self.warnings.push(w);
        } else {
            self.more_warnings += 1;
        }
    }

    /// One warning per `<text>` element of the source `text` when no font is loaded (usvg then
    /// lays out none: text is out of scope), so a picture without its text says so. With fonts,
    /// text anywhere (pattern tiles and nested SVG images too) is drawn and nothing is said.
    pub(super) fn text_warnings(&mut self, text: &str) {
        if self.images.has_fonts() {
            return;
        }
        let Some(doc) = super::import_paint::source_tree(text) else {
            return;
        };
        for node in doc.descendants().filter(|n| n.has_tag_name("text")) {
            let on = match node.attribute("id") {
                Some(id) => format!("<text id=\"{id}\">"),
                None => "a <text>".to_string(),
            };
            self.warn(format!("{on} ignored (text is not drawn: no fonts)"));
        }
    }

    pub(super) fn finish(mut self) -> Vec<String> {
        if self.more_warnings > 0 {
            let n = self.more_warnings;
            self.warnings.push(format!("{n} more warnings like these"));
        }
        self.warnings
    }

    /// Warns about what `g` asks for that the scene cannot draw (filters).
    fn unsupported(&mut self, g: &usvg::Group) {
        let on = element(g);
        if !g.filters().is_empty() {
            self.warn(format!(
                "filter on {on} ignored (filters are not drawn): drawn unfiltered"
            ));
        }
    }

    /// Adds what `g` draws to `out`. `parent` maps the user space of `g`'s parent to the canvas.
    /// Transforms are chained here as resvg draws them (usvg's `abs_transform` of a `<use>`
    /// group leaves out the group's own transform, and inside a clip path or mask it starts at
    /// the content's root).
    pub(super) fn group(
        &mut self,
        g: &usvg::Group,
        parent: Transform,
        mode: Mode,
        out: &mut Content,
    ) {
        self.unsupported(g);
        let ts = parent.pre_concat(g.transform());
        let opacity = match mode {
            Mode::Draw => g.opacity().get(),
            Mode::Clip => 1.0,
        };
        let clip = g.clip_path().map(|c| self.clip(c, ts));
        let mask = match mode {
            Mode::Draw => g.mask().map(|m| self.mask(m, ts)),
            Mode::Clip => None,
        };
        let blend = self.blend(g, mode);
        // `isolation: isolate` is a layer of its own (every scene group is isolated).
        let isolated = mode == Mode::Draw && (g.isolate() || !blend.is_normal());
        let layered = opacity < 1.0 || clip.is_some() || mask.is_some() || isolated;
        let (start, gi) = (out.shapes.len(), out.groups.len());
        if layered {
            // Reserved now so that it comes before the groups inside it.
            out.groups.push(Group::new(start..start, opacity));
        }
        for node in g.children() {
            match node {
                usvg::Node::Group(child) => self.group(child, ts, mode, out),
                usvg::Node::Path(p) if p.is_visible() => match mode {
                    Mode::Draw => path_shapes(p, ts, 1.0, &mut out.shapes),
                    Mode::Clip => clip_shape(p, ts, &mut out.shapes),
                },
                usvg::Node::Path(_) => {}
                // A clip path clips by shapes and text only.
                usvg::Node::Image(_) if mode == Mode::Clip => {}
                usvg::Node::Image(i) => {
                    let images = Arc::clone(&self.images);
                    super::import_image::image(self, &images, i, ts, out);
                }
                usvg::Node::Text(t) => self.group(t.flattened(), ts, mode, out),
            }
        }
        if !layered {
            return;
        }
        let end = out.shapes.len();
        if end == start {
            out.groups.truncate(gi);
        } else if clip.is_none() && mask.is_none() && !isolated && end - start == 1
            // A group inside (a blend mode) needs this layer below it.
            && out.groups.len() == gi + 1
        {
            // One shape painting one layer: the opacity is exact on the shape itself.
            if fold_opacity(&mut out.shapes[start], opacity) {
                out.groups.remove(gi);
                return;
            }
        }
        if end > start {
            out.groups[gi] = Group {
                start,
                end,
                opacity,
                clip: clip.map(Box::new),
                mask: mask.map(Box::new),
                blend,
            };
        }
    }

    /// The blend mode of `g` (normal inside a clip path; `plus-lighter` drawn as normal with
    /// a warning).
    fn blend(&mut self, g: &usvg::Group, mode: Mode) -> BlendMode {
        if mode == Mode::Clip {
            return BlendMode::Normal;
        }
        blend_mode(g.blend_mode()).unwrap_or_else(|| {
            self.warn(format!(
                "mix-blend-mode {} on {} not drawn (not a W3C Compositing Level 1 mode): \
                 drawn as normal",
                g.blend_mode(),
                element(g)
            ));
            BlendMode::Normal
        })
    }

    /// A clip path applied in user space `ts`: its children (under its own transform) and the
    /// clip path on it.
    fn clip(&mut self, c: &usvg::ClipPath, ts: Transform) -> Clip {
        let mut content = Content::default();
        self.group(
            c.root(),
            ts.pre_concat(c.transform()),
            Mode::Clip,
            &mut content,
        );
        Clip {
            content,
            clip: c.clip_path().map(|inner| Box::new(self.clip(inner, ts))),
        }
    }

    /// A mask applied in user space `ts`: its children clipped to its region, and the mask on
    /// it.
    fn mask(&mut self, m: &usvg::Mask, ts: Transform) -> Mask {
        let mut content = Content::default();
        self.group(m.root(), ts, Mode::Draw, &mut content);
        if let Some(region) = rect_shape(m.rect(), ts)
            && !content.shapes.is_empty()
            && !self.covers_canvas(&region)
        {
            let mut g = Group::new(0..content.shapes.len(), 1.0);
            g.clip = Some(Box::new(Clip {
                content: Content {
                    shapes: vec![region],
                    groups: Vec::new(),
                },
                clip: None,
            }));
            content.groups.insert(0, g);
        }
        Mask {
            kind: match m.kind() {
                usvg::MaskType::Luminance => MaskKind::Luminance,
                usvg::MaskType::Alpha => MaskKind::Alpha,
            },
            content,
            mask: m.mask().map(|inner| Box::new(self.mask(inner, ts))),
        }
    }

    /// Whether an axis-aligned rectangle `s` contains the whole canvas.
    fn covers_canvas(&self, s: &Shape) -> bool {
        let (lo, hi) = s.control_bounds();
        let (w, h) = self.canvas;
        // Every point (anchors and the thirds of the edges) on one of the four sides.
        let on_side = |p: &crate::scene::Point| {
            let near = |a: f32, b: f32| (a - b).abs() <= 1e-4 * (1.0 + b.abs());
            near(p.x, lo.x) || near(p.x, hi.x) || near(p.y, lo.y) || near(p.y, hi.y)
        };
        let axis = s.points.iter().all(on_side) && s.points.len() == 12;
        axis && lo.x <= 0.0 && lo.y <= 0.0 && hi.x >= w && hi.y >= h
    }
}

/// The element a group of usvg's stands for, as warnings name it.
fn element(g: &usvg::Group) -> String {
    // usvg gives the group of a `<g>` or `<use>` its id, and the single path of another
    // element that needed a group (`<rect filter=…>`) the element's id.
    let id = match g.children() {
        _ if !g.id().is_empty() => g.id(),
        [only] => only.id(),
        _ => "",
    };
    if id.is_empty() {
        "an element without an id".to_string()
    } else {
        format!("#{id}")
    }
}

/// The scene's blend mode for usvg's (`None`: `plus-lighter`, which is not one of them).
fn blend_mode(b: usvg::BlendMode) -> Option<BlendMode> {
    use usvg::BlendMode as U;
    Some(match b {
        U::Normal => BlendMode::Normal,
        U::Multiply => BlendMode::Multiply,
        U::Screen => BlendMode::Screen,
        U::Overlay => BlendMode::Overlay,
        U::Darken => BlendMode::Darken,
        U::Lighten => BlendMode::Lighten,
        U::ColorDodge => BlendMode::ColorDodge,
        U::ColorBurn => BlendMode::ColorBurn,
        U::HardLight => BlendMode::HardLight,
        U::SoftLight => BlendMode::SoftLight,
        U::Difference => BlendMode::Difference,
        U::Exclusion => BlendMode::Exclusion,
        U::Hue => BlendMode::Hue,
        U::Saturation => BlendMode::Saturation,
        U::Color => BlendMode::Color,
        U::Luminosity => BlendMode::Luminosity,
        U::PlusLighter => return None,
    })
}

/// Multiplies `opacity` into the one layer `s` paints; false when it paints two (a visible
/// fill and a stroke, which overlap).
fn fold_opacity(s: &mut Shape, opacity: f32) -> bool {
    // A texture paints instead of the flat colour that would carry its opacity: a layer does.
    if s.gradients.as_ref().is_some_and(|g| g.texture.is_some()) {
        return false;
    }
    let on_fill = match (&mut s.fill, &mut s.stroke) {
        (Some(f), None) => {
            f.a *= opacity;
            true
        }
        (None, Some(st)) => {
            st.color.a *= opacity;
            false
        }
        (Some(f), Some(st)) if f.a == 0.0 => {
            st.color.a *= opacity;
            false
        }
        _ => return false,
    };
    // A gradient is drawn from its stops (the flat colour only stands in for it).
    if let Some(g) = s.gradients.as_deref_mut() {
        let g = if on_fill { &mut g.fill } else { &mut g.stroke };
        for stop in g.iter_mut().flat_map(|g| g.stops.iter_mut()) {
            stop.color.a *= opacity;
        }
    }
    true
}

/// The rectangle `r` in user space `ts`, as the clip shape of a `<rect>` there.
pub(super) fn rect_shape(r: usvg::NonZeroRect, ts: Transform) -> Option<Shape> {
    let path = usvg::tiny_skia_path::PathBuilder::from_rect(r.to_rect());
    let mut shapes = Vec::new();
    clip_path_shape(&path, ts, crate::scene::FillRule::NonZero, &mut shapes);
    shapes.pop()
}
