//! The SVG writer for scenes with groups: every group a `<g>` (with `opacity`, `clip-path`,
//! `mask`, and `style="mix-blend-mode:…"` or, when nothing else isolates it,
//! `style="isolation:isolate"`), every clip a `<clipPath>` and every mask a `<mask>` in one `<defs>` before the
//! drawing, with ids `clip1`, `clip2`, … and `mask1`, … in the order they are first needed
//! (so the same scene gives the same document). Everything is in canvas units
//! (`clipPathUnits` and `maskUnits` `userSpaceOnUse`, a mask region of the whole canvas); paths
//! are written one by one with all their paint attributes (no shared-attribute groups), a
//! gradient or texture as in the other writer ([`PaintDefs`]: ids `g1`, `g2`, … in the order
//! the paths are written, mask content included; one element for identical ones).
//!
//! SVG allows no `<g>` inside a `<clipPath>`: a clip content's group clip is written on each of
//! its paths.

use super::export::{Inherited, Paint, Writer, num, opacity_decimals, push_attr, push_paint};
use super::export_paint::PaintDefs;
use super::path_data::push_path_data;
use crate::scene::{Clip, Group, Mask, MaskKind, Shape};

/// Finishes `w` (header written) for a scene with groups.
pub(super) fn layered(w: Writer<'_>) -> String {
    let scene = w.scene;
    let mut x = Layered {
        defs: String::new(),
        clips: 0,
        masks: 0,
        paints: PaintDefs::default(),
        p: w.p,
        size: (scene.width, scene.height),
    };
    let mut body = String::new();
    x.content(&scene.shapes, &scene.groups, &mut body);
    let mut out = w.out;
    if !(x.defs.is_empty() && x.paints.text.is_empty()) {
        out.push_str("<defs>\n");
        out.push_str(&x.paints.text);
        out.push_str(&x.defs);
        out.push_str("</defs>\n");
    }
    out.push_str(&body);
    out.push_str("</svg>\n");
    out
}

struct Layered {
    defs: String,
    clips: usize,
    masks: usize,
    /// The gradients and textures (ids `g1`, `g2`, …), written before the clips and masks.
    paints: PaintDefs,
    /// Decimals of coordinates.
    p: usize,
    size: (u32, u32),
}

impl Layered {
    /// Writes `shapes` with their `groups` (see [`crate::scene::Group`]) into `out`.
    fn content(&mut self, shapes: &[Shape], groups: &[Group], out: &mut String) {
        let mut next = 0;
        let mut open: Vec<usize> = Vec::new();
        for (i, sh) in shapes.iter().enumerate() {
            while open.last().is_some_and(|&end| end <= i) {
                open.pop();
                out.push_str("</g>\n");
            }
            while next < groups.len() && groups[next].start <= i {
                self.open_group(&groups[next], out);
                open.push(groups[next].end);
                next += 1;
            }
            let ids = self.paints.of_shape(sh);
            let paint = Paint::of(sh, self.p, &ids);
            if paint.visible() {
                self.path_start(sh, out);
                push_paint(out, &paint, &Inherited::root());
                out.push_str("/>\n");
            }
        }
        out.extend(open.iter().map(|_| "</g>\n"));
    }

    fn path_start(&self, sh: &Shape, out: &mut String) {
        out.push_str(r#"<path d=""#);
        push_path_data(out, sh, self.p);
        out.push('"');
    }

    fn open_group(&mut self, g: &Group, out: &mut String) {
        let clip = g.clip.as_deref().map(|c| self.clip(c));
        let mask = g.mask.as_deref().map(|m| self.mask(m));
        out.push_str("<g");
        if g.opacity < 1.0 {
            let o = num(g.opacity, opacity_decimals(self.p));
            push_attr(out, "opacity", &o);
        }
        if let Some(id) = clip {
            push_attr(out, "clip-path", &format!("url(#{id})"));
        }
        if let Some(id) = mask {
            push_attr(out, "mask", &format!("url(#{id})"));
        }
        // Both are CSS properties, read from `style` only (as resvg and browsers do). Every
        // scene group is isolated; one that nothing else isolates says so.
        if !g.blend.is_normal() {
            let css = format!("mix-blend-mode:{}", g.blend.css_name());
            push_attr(out, "style", &css);
        } else if g.opacity >= 1.0 && g.clip.is_none() && g.mask.is_none() {
            push_attr(out, "style", "isolation:isolate");
        }
        out.push_str(">\n");
    }

    /// Writes `c` (and what it refers to) into the defs; returns its id.
    fn clip(&mut self, c: &Clip) -> String {
        let inner = c.clip.as_deref().map(|c| self.clip(c));
        // The clip of the innermost group around each shape, written on the shape.
        let mut shape_clip: Vec<Option<String>> = vec![None; c.content.shapes.len()];
        for g in &c.content.groups {
            if let Some(gc) = &g.clip {
                let id = self.clip(gc);
                shape_clip[g.start..g.end].fill(Some(id));
            }
        }
        self.clips += 1;
        let id = format!("clip{}", self.clips);
        let mut el = String::new();
        el.push_str("<clipPath");
        push_attr(&mut el, "id", &id);
        push_attr(&mut el, "clipPathUnits", "userSpaceOnUse");
        if let Some(i) = inner {
            push_attr(&mut el, "clip-path", &format!("url(#{i})"));
        }
        el.push_str(">\n");
        for (sh, sc) in c.content.shapes.iter().zip(&shape_clip) {
            self.path_start(sh, &mut el);
            if !sh.fill_rule.is_nonzero() {
                push_attr(&mut el, "clip-rule", "evenodd");
            }
            if let Some(i) = sc {
                push_attr(&mut el, "clip-path", &format!("url(#{i})"));
            }
            el.push_str("/>\n");
        }
        el.push_str("</clipPath>\n");
        self.defs.push_str(&el);
        id
    }

    /// Writes `m` (and what it refers to) into the defs; returns its id.
    fn mask(&mut self, m: &Mask) -> String {
        let inner = m.mask.as_deref().map(|m| self.mask(m));
        let mut body = String::new();
        self.content(&m.content.shapes, &m.content.groups, &mut body);
        self.masks += 1;
        let id = format!("mask{}", self.masks);
        let (w, h) = self.size;
        let mut el = String::new();
        el.push_str("<mask");
        push_attr(&mut el, "id", &id);
        push_attr(&mut el, "maskUnits", "userSpaceOnUse");
        el.push_str(&format!(r#" x="0" y="0" width="{w}" height="{h}""#));
        if m.kind == MaskKind::Alpha {
            push_attr(&mut el, "mask-type", "alpha");
        }
        if let Some(i) = inner {
            push_attr(&mut el, "mask", &format!("url(#{i})"));
        }
        el.push_str(">\n");
        el.push_str(&body);
        el.push_str("</mask>\n");
        self.defs.push_str(&el);
        id
    }
}
