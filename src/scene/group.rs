//! Groups: runs of consecutive shapes composited as one layer, with an opacity, a clip and a
//! mask (SVG's `<g opacity clip-path mask>`, nested `<svg>`/`<symbol>` viewports as clips).
//!
//! A scene without groups is the flat list of shapes painted in order, and everything that
//! works on [`Scene::shapes`] (LIVE, SDS, the palette, export) keeps working on it unchanged.
//! A group only names a range of that list: its shapes are painted, in order, onto a
//! transparent layer, and the layer is composited over what lies below with
//! `alpha × opacity × clip × mask`, per pixel, by its [`BlendMode`] (W3C Compositing: blend
//! with what lies below, then source-over). Every group is an isolated group in that spec's
//! sense (its layer starts transparent), so SVG's `isolation: isolate` is a group with nothing
//! else set, and a shape's blend mode is a group of that one shape.
//!
//! # Invariants (checked by [`validate_groups`], from [`Scene::validate`])
//! - Every group's range `start..end` is non-empty and inside its shape list.
//! - Two ranges are nested or disjoint; the list is sorted by `start`, an outer group before an
//!   inner one with the same start (so groups open in list order and close innermost first).
//! - `opacity` is finite and in `[0, 1]`.
//! - A clip's shapes are closed and unstroked; their fill colour is ignored (a clip is the
//!   union of its shapes' covered areas, each by its own [`FillRule`], SVG's `clip-rule`).
//! - The content of a clip or mask obeys the same invariants (recursively), and is drawn in
//!   canvas pixels like the scene: units (`clipPathUnits`, `maskUnits`, `maskContentUnits`) and
//!   the mask region are resolved at import.
//!
//! Clip and mask content are not optimised: [`super::Params`] holds the shapes of
//! [`Scene::shapes`] and one opacity per group of [`Scene::groups`].
//!
//! [`Scene::shapes`]: super::Scene::shapes
//! [`Scene::groups`]: super::Scene::groups
//! [`Scene::validate`]: super::Scene::validate

use super::{Point, Scene, SceneError, Shape};
use serde::{Deserialize, Serialize};

impl Scene {
    /// Replaces shape `i` by `pieces[i]` (none, itself, or several shapes in its place in the
    /// paint order), keeping every group on the pieces of the shapes it had; a group left
    /// without shapes is dropped. `pieces` has one entry per shape (missing entries remove
    /// their shapes). What the vector finish uses to split, drop and merge shapes of a scene
    /// with groups.
    pub fn replace_shapes(&mut self, pieces: Vec<Vec<Shape>>) {
        // `at[k]`: the new index of old shape k's first piece; `at[n]`: the new length.
        let n = self.shapes.len();
        let mut at = Vec::with_capacity(n + 1);
        let mut shapes = Vec::with_capacity(n);
        let mut pieces = pieces.into_iter();
        for _ in 0..n {
            at.push(shapes.len());
            shapes.extend(pieces.next().unwrap_or_default());
        }
        at.push(shapes.len());
        for g in &mut self.groups {
            g.start = at[g.start.min(n)];
            g.end = at[g.end.min(n)];
        }
        self.groups.retain(|g| g.start < g.end);
        self.shapes = shapes;
    }
}

/// Which points a closed outline covers (SVG `fill-rule`, `clip-rule`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FillRule {
    /// Where the winding number is not zero.
    #[default]
    NonZero,
    /// Where the winding number is odd.
    EvenOdd,
}

impl FillRule {
    pub fn is_nonzero(&self) -> bool {
        *self == FillRule::NonZero
    }
}

/// Consecutive shapes composited as one layer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Group {
    /// First shape of the group (index into the list the group belongs to).
    pub start: usize,
    /// One past the last shape.
    pub end: usize,
    /// Multiplies the layer's alpha.
    pub opacity: f32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clip: Option<Box<Clip>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<Box<Mask>>,
    /// How the layer mixes with what lies below (CSS `mix-blend-mode`).
    #[serde(default, skip_serializing_if = "BlendMode::is_normal")]
    pub blend: BlendMode,
}

/// A blend mode of the W3C Compositing spec (CSS `mix-blend-mode`): how a group's colour is
/// mixed with the colour below before source-over. The first eleven after `Normal` are
/// separable (channel by channel); the last four mix hue, saturation and luminosity.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BlendMode {
    #[default]
    Normal,
    Multiply,
    Screen,
    Overlay,
    Darken,
    Lighten,
    ColorDodge,
    ColorBurn,
    HardLight,
    SoftLight,
    Difference,
    Exclusion,
    Hue,
    Saturation,
    Color,
    Luminosity,
}

impl BlendMode {
    pub fn is_normal(&self) -> bool {
        *self == BlendMode::Normal
    }

    /// The CSS keyword (`color-dodge`), as SVG's `mix-blend-mode` writes it.
    pub fn css_name(self) -> &'static str {
        use BlendMode::*;
        match self {
            Normal => "normal",
            Multiply => "multiply",
            Screen => "screen",
            Overlay => "overlay",
            Darken => "darken",
            Lighten => "lighten",
            ColorDodge => "color-dodge",
            ColorBurn => "color-burn",
            HardLight => "hard-light",
            SoftLight => "soft-light",
            Difference => "difference",
            Exclusion => "exclusion",
            Hue => "hue",
            Saturation => "saturation",
            Color => "color",
            Luminosity => "luminosity",
        }
    }
}

impl Group {
    /// A group of `range` with this opacity, no clip and no mask.
    pub fn new(range: std::ops::Range<usize>, opacity: f32) -> Self {
        Group {
            start: range.start,
            end: range.end,
            opacity,
            clip: None,
            mask: None,
            blend: BlendMode::Normal,
        }
    }

    /// The same group with every point of its clip and mask moved by `f` (stroke widths of
    /// mask content multiplied by `stroke_k`).
    pub fn mapped(&self, f: &impl Fn(&Point) -> Point, stroke_k: f32) -> Group {
        Group {
            clip: self.clip.as_ref().map(|c| Box::new(c.mapped(f, stroke_k))),
            mask: self.mask.as_ref().map(|m| Box::new(m.mapped(f, stroke_k))),
            ..*self
        }
    }
}

/// Shapes with their own groups: what a clip or a mask draws.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Content {
    pub shapes: Vec<Shape>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub groups: Vec<Group>,
}

impl Content {
    fn mapped(&self, f: &impl Fn(&Point) -> Point, stroke_k: f32) -> Content {
        Content {
            shapes: self.shapes.iter().map(|s| s.mapped(f, stroke_k)).collect(),
            groups: self.groups.iter().map(|g| g.mapped(f, stroke_k)).collect(),
        }
    }

    fn validate(&self, what: &str) -> Result<(), SceneError> {
        for (i, s) in self.shapes.iter().enumerate() {
            s.validate(i)
                .map_err(|e| SceneError::Group(format!("{what}: {e}")))?;
        }
        validate_groups(&self.groups, self.shapes.len())
            .map_err(|e| SceneError::Group(format!("{what}: {e}")))
    }
}

/// A clip path: the union of its shapes' areas, times its own clip when it has one (SVG's
/// `clip-path` on a `<clipPath>`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Clip {
    pub content: Content,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clip: Option<Box<Clip>>,
}

impl Clip {
    fn mapped(&self, f: &impl Fn(&Point) -> Point, stroke_k: f32) -> Clip {
        Clip {
            content: self.content.mapped(f, stroke_k),
            clip: self.clip.as_ref().map(|c| Box::new(c.mapped(f, stroke_k))),
        }
    }

    fn validate(&self) -> Result<(), SceneError> {
        self.content.validate("clip")?;
        if let Some(i) = self
            .content
            .shapes
            .iter()
            .position(|s| !s.is_closed() || s.stroke.is_some())
        {
            return Err(SceneError::Group(format!(
                "clip shape {i} must be closed and unstroked"
            )));
        }
        self.clip.as_ref().map_or(Ok(()), |c| c.validate())
    }
}

/// How a mask's drawing becomes a factor per pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaskKind {
    /// `0.2125 r + 0.7154 g + 0.0721 b` of the premultiplied colour (SVG's default, as resvg).
    #[default]
    Luminance,
    /// The alpha channel.
    Alpha,
}

impl MaskKind {
    /// SVG's luminance of a colour: `r, g, b` weighed by these (as resvg), which the rasteriser
    /// and the PDF export of a luminance mask both read.
    pub const LUMINANCE_WEIGHTS: [f64; 3] = [0.2125, 0.7154, 0.0721];
}

/// A mask: its content drawn over transparency, reduced per pixel by `kind`, times its own mask
/// when it has one (SVG's `mask` on a `<mask>`). The mask region is part of the content (a
/// clipped group) when it does not cover the canvas.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Mask {
    pub kind: MaskKind,
    pub content: Content,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<Box<Mask>>,
}

impl Mask {
    fn mapped(&self, f: &impl Fn(&Point) -> Point, stroke_k: f32) -> Mask {
        Mask {
            kind: self.kind,
            content: self.content.mapped(f, stroke_k),
            mask: self.mask.as_ref().map(|m| Box::new(m.mapped(f, stroke_k))),
        }
    }

    fn validate(&self) -> Result<(), SceneError> {
        self.content.validate("mask")?;
        self.mask.as_ref().map_or(Ok(()), |m| m.validate())
    }
}

/// Checks the invariants in the module docs for `groups` over a list of `n` shapes.
pub(crate) fn validate_groups(groups: &[Group], n: usize) -> Result<(), SceneError> {
    let err = |i: usize, reason: &str| Err(SceneError::Group(format!("group {i}: {reason}")));
    // Ends of the groups still open, innermost last.
    let mut open: Vec<usize> = Vec::new();
    let mut prev_start = 0;
    for (i, g) in groups.iter().enumerate() {
        if !(g.start < g.end && g.end <= n) {
            return err(
                i,
                &format!("range {}..{} is empty or past {n}", g.start, g.end),
            );
        }
        if g.start < prev_start {
            return err(i, "groups must be sorted by their first shape");
        }
        prev_start = g.start;
        while open.last().is_some_and(|&e| e <= g.start) {
            open.pop();
        }
        if open.last().is_some_and(|&e| g.end > e) {
            return err(i, "overlaps an enclosing group without nesting in it");
        }
        open.push(g.end);
        if !(g.opacity.is_finite() && (0.0..=1.0).contains(&g.opacity)) {
            return err(i, "opacity must be finite and in [0, 1]");
        }
        if let Some(c) = &g.clip {
            c.validate()
                .map_err(|e| SceneError::Group(format!("group {i}: {e}")))?;
        }
        if let Some(m) = &g.mask {
            m.validate()
                .map_err(|e| SceneError::Group(format!("group {i}: {e}")))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Rgba, Scene, Stroke};

    fn scene(n: usize) -> Scene {
        let mut s = Scene::new(16, 16, Rgba::WHITE).unwrap();
        for i in 0..n {
            s.shapes
                .push(Shape::square(i as f32, 1.0, 4.0, Rgba::BLACK).unwrap());
        }
        s
    }

    #[test]
    fn ranges_must_nest_and_be_sorted() {
        let mut s = scene(4);
        s.groups = vec![
            Group::new(0..4, 0.5),
            Group::new(0..2, 1.0),
            Group::new(2..3, 0.2),
        ];
        assert_eq!(s.validate(), Ok(()));
        s.groups = vec![Group::new(0..2, 0.5), Group::new(1..3, 1.0)];
        assert!(s.validate().is_err(), "crossing ranges");
        s.groups = vec![Group::new(2..3, 0.5), Group::new(0..1, 1.0)];
        assert!(s.validate().is_err(), "unsorted");
        s.groups = vec![Group::new(0..5, 0.5)];
        assert!(s.validate().is_err(), "past the end");
        s.groups = vec![Group::new(1..1, 0.5)];
        assert!(s.validate().is_err(), "empty");
        s.groups = vec![Group::new(0..1, 1.5)];
        assert!(s.validate().is_err(), "opacity");
    }

    #[test]
    fn replacing_shapes_keeps_groups_on_their_pieces() {
        let mut s = scene(4);
        s.groups = vec![
            Group::new(0..4, 0.5),
            Group::new(1..3, 1.0),
            Group::new(3..4, 0.2),
        ];
        let sq = |x: f32| Shape::square(x, 1.0, 2.0, Rgba::BLACK).unwrap();
        // Shape 1 split in three, shape 3 dropped (its group with it).
        s.replace_shapes(vec![
            vec![sq(0.0)],
            vec![sq(1.0), sq(2.0), sq(3.0)],
            vec![sq(4.0)],
        ]);
        assert_eq!(s.shapes.len(), 5);
        let ranges: Vec<_> = s.groups.iter().map(|g| (g.start, g.end)).collect();
        assert_eq!(ranges, vec![(0, 5), (1, 5)]);
        assert_eq!(s.validate(), Ok(()));
        assert_eq!(s.shapes[4], sq(4.0));
    }

    #[test]
    fn clip_shapes_must_be_closed_fills() {
        let mut s = scene(2);
        let line = Shape::open_cubic(vec![Point::default(); 4], Stroke::round(Rgba::BLACK, 1.0));
        let clip = |shapes: Vec<Shape>| Clip {
            content: Content {
                shapes,
                groups: Vec::new(),
            },
            clip: None,
        };
        let mut g = Group::new(0..2, 1.0);
        g.clip = Some(Box::new(clip(vec![line.unwrap()])));
        s.groups = vec![g.clone()];
        assert!(s.validate().is_err());
        g.clip = Some(Box::new(clip(vec![
            Shape::square(2.0, 2.0, 3.0, Rgba::BLACK).unwrap(),
        ])));
        s.groups = vec![g];
        assert_eq!(s.validate(), Ok(()));
        let back: Scene = serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
        assert_eq!(back, s);
    }
}
