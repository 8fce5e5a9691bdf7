//! Groups in the PDF: each group's shapes are a form XObject (an isolated transparency group,
//! as the rasteriser's layers are), painted through a graphics state with the group's opacity
//! and blend mode, inside its clip, under its mask.
//!
//! - A clip of one shape (with no groups of its own) is a clipping path (`W n` or `W* n`), so a
//!   designer's tool shows it as a clipping path; any other clip (several shapes, each by its
//!   own fill rule, whose union a clipping path cannot always say) is an alpha soft mask of its
//!   shapes filled opaque. A clip's own clip intersects it either way.
//! - A mask is a soft mask of its content, read by its luminosity or its alpha; a mask's own
//!   mask masks the content first. PDF computes luminosity with the weights of its
//!   non-separable blend modes (0.30, 0.59, 0.11) where SVG uses 0.2125, 0.7154, 0.0721, so a
//!   luminance mask's colours, gradient stops and texels are written as greys of SVG's
//!   luminance, which PDF reads back unchanged (a blend mode inside a mask mixes the greys).

use super::{Channel, Doc, Mode, State, path};
use crate::scene::{Clip, Content, Group, Mask, MaskKind, Shape};
use std::fmt::Write as _;

impl<'a> Doc<'a> {
    /// Group `g` of `shapes` (`inner`: the groups inside it) as a form, painted.
    pub(super) fn group(
        &mut self,
        out: &mut String,
        shapes: &'a [Shape],
        g: &'a Group,
        inner: &'a [Group],
        mode: Mode,
    ) {
        let on_page = std::mem::replace(&mut self.on_page, false);
        let mut body = String::new();
        self.draw(&mut body, shapes, inner, g.start..g.end, mode);
        let mut form = self.form(body);
        if let Some(m) = &g.mask {
            form = self.masked(form, m);
        }
        let mut head = String::new();
        if let Some(c) = &g.clip {
            self.clip(&mut head, c);
        }
        self.on_page = on_page;
        out.push_str("q\n");
        out.push_str(&head);
        if g.opacity < 1.0 || !g.blend.is_normal() {
            let _ = write!(out, "{} gs ", self.state(State::Group(g.opacity, g.blend)));
        }
        let _ = writeln!(out, "/X{form} Do Q");
    }

    /// A form drawing a clip's or a mask's content; its index.
    fn content_form(&mut self, content: &'a Content, mode: Mode) -> usize {
        let mut body = String::new();
        let n = content.shapes.len();
        self.draw(&mut body, &content.shapes, &content.groups, 0..n, mode);
        self.form(body)
    }

    /// A form that paints form `form` under mask `m`; its index.
    fn masked(&mut self, form: usize, m: &'a Mask) -> usize {
        // A luminance mask's content in SVG's luminance, as greys PDF's luminosity keeps.
        let channel = self.channel;
        if m.kind == MaskKind::Luminance {
            self.channel = Channel::Luminance;
        }
        let mut content = self.content_form(&m.content, Mode::Paint);
        self.channel = channel;
        if let Some(inner) = &m.mask {
            content = self.masked(content, inner);
        }
        let gs = self.state(State::SoftMask {
            luminosity: m.kind == MaskKind::Luminance,
            form: content,
        });
        self.form(format!("q {gs} gs /X{form} Do Q\n"))
    }

    /// Writes what restricts painting to clip `c`: a clipping path, or a soft mask's graphics
    /// state.
    fn clip(&mut self, out: &mut String, c: &'a Clip) {
        if let ([shape], []) = (&c.content.shapes[..], &c.content.groups[..]) {
            path(out, shape);
            out.push_str(if shape.fill_rule.is_nonzero() {
                "W n\n"
            } else {
                "W* n\n"
            });
            if let Some(inner) = &c.clip {
                self.clip(out, inner);
            }
            return;
        }
        let mut form = self.content_form(&c.content, Mode::Clip);
        if let Some(inner) = &c.clip {
            let mut head = String::new();
            self.clip(&mut head, inner);
            form = self.form(format!("q\n{head}/X{form} Do Q\n"));
        }
        let gs = self.state(State::SoftMask {
            luminosity: false,
            form,
        });
        let _ = writeln!(out, "{gs} gs");
    }
}

/// The PDF name of a blend mode (PDF has all of CSS's).
pub(super) fn blend_name(b: crate::scene::BlendMode) -> &'static str {
    use crate::scene::BlendMode::*;
    match b {
        Normal => "Normal",
        Multiply => "Multiply",
        Screen => "Screen",
        Overlay => "Overlay",
        Darken => "Darken",
        Lighten => "Lighten",
        ColorDodge => "ColorDodge",
        ColorBurn => "ColorBurn",
        HardLight => "HardLight",
        SoftLight => "SoftLight",
        Difference => "Difference",
        Exclusion => "Exclusion",
        Hue => "Hue",
        Saturation => "Saturation",
        Color => "Color",
        Luminosity => "Luminosity",
    }
}
