//! The flat parameter view of a [`Scene`]: one `Vec<f32>` per [`ParamGroup`], in shape order.
//!
//! Layout (all in shape order, skipping shapes that lack the attribute):
//! - `Points`: `x, y` for every point of every shape.
//! - `Fill`: `r, g, b, a` for every shape with a fill.
//! - `Stroke`: `r, g, b, a` for every shape with a stroke.
//! - `Width`: one stroke width for every shape with a stroke.
//! - `Background`: `r, g, b, a`.
//!
//! Gradients from the rasteriser use the same type and layout, so an optimiser can walk the
//! groups of parameters and gradients side by side.

use super::{Point, Rgba, Scene, SceneError};
use serde::{Deserialize, Serialize};

/// A named group of scene parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ParamGroup {
    Points,
    Fill,
    Stroke,
    Width,
    Background,
}

impl ParamGroup {
    pub const ALL: [ParamGroup; 5] = [
        ParamGroup::Points,
        ParamGroup::Fill,
        ParamGroup::Stroke,
        ParamGroup::Width,
        ParamGroup::Background,
    ];

    fn index(self) -> usize {
        self as usize
    }
}

/// Which groups an optimiser may change (e.g. pixel art: colours only; sketch: points only).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Trainable {
    pub points: bool,
    pub fill: bool,
    pub stroke: bool,
    pub width: bool,
    pub background: bool,
}

impl Trainable {
    pub const ALL: Trainable = Trainable {
        points: true,
        fill: true,
        stroke: true,
        width: true,
        background: true,
    };
    pub const NONE: Trainable = Trainable {
        points: false,
        fill: false,
        stroke: false,
        width: false,
        background: false,
    };

    pub fn contains(&self, g: ParamGroup) -> bool {
        match g {
            ParamGroup::Points => self.points,
            ParamGroup::Fill => self.fill,
            ParamGroup::Stroke => self.stroke,
            ParamGroup::Width => self.width,
            ParamGroup::Background => self.background,
        }
    }
}

/// Flat parameters (or gradients) of a scene, one vector per group.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Params {
    groups: [Vec<f32>; 5],
}

impl Params {
    /// All-zero parameters with the layout of `scene` (the shape of a gradient).
    pub fn zeros_like(scene: &Scene) -> Self {
        let n_points = scene.num_points();
        let n_fill = scene.shapes.iter().filter(|s| s.fill.is_some()).count();
        let n_stroke = scene.shapes.iter().filter(|s| s.stroke.is_some()).count();
        Params {
            groups: [
                vec![0.0; 2 * n_points],
                vec![0.0; 4 * n_fill],
                vec![0.0; 4 * n_stroke],
                vec![0.0; n_stroke],
                vec![0.0; 4],
            ],
        }
    }

    /// Reads the parameters out of `scene`.
    pub fn from_scene(scene: &Scene) -> Self {
        let mut p = Params::zeros_like(scene);
        let [pts, fill, stroke, width, bg] = &mut p.groups;
        let (mut ip, mut if_, mut is) = (0, 0, 0);
        for sh in &scene.shapes {
            for q in &sh.points {
                pts[ip] = q.x;
                pts[ip + 1] = q.y;
                ip += 2;
            }
            if let Some(f) = sh.fill {
                fill[if_..if_ + 4].copy_from_slice(&f.to_array());
                if_ += 4;
            }
            if let Some(s) = sh.stroke {
                stroke[4 * is..4 * is + 4].copy_from_slice(&s.color.to_array());
                width[is] = s.width;
                is += 1;
            }
        }
        bg.copy_from_slice(&scene.background.to_array());
        p
    }

    /// Writes the parameters back into `scene`, clamping colours into `[0, 1]` and widths to
    /// `>= 0` so the scene stays valid. Non-finite point coordinates are rejected and leave the
    /// scene unchanged.
    pub fn write_to(&self, scene: &mut Scene) -> Result<(), SceneError> {
        let expected = Params::zeros_like(scene);
        for g in ParamGroup::ALL {
            let (got, exp) = (self.get(g).len(), expected.get(g).len());
            if got != exp {
                return Err(SceneError::ParamLength {
                    group: g,
                    got,
                    expected: exp,
                });
            }
        }
        if let Some(i) = self
            .get(ParamGroup::Points)
            .iter()
            .position(|v| !v.is_finite())
        {
            return Err(SceneError::Shape {
                shape: usize::MAX,
                reason: format!("point coordinate {i} is not finite"),
            });
        }
        let [pts, fill, stroke, width, bg] = &self.groups;
        let (mut ip, mut if_, mut is) = (0, 0, 0);
        let rgba = |s: &[f32]| Rgba::new(s[0], s[1], s[2], s[3]).clamped();
        for sh in &mut scene.shapes {
            for q in &mut sh.points {
                *q = Point::new(pts[ip], pts[ip + 1]);
                ip += 2;
            }
            if let Some(f) = &mut sh.fill {
                *f = rgba(&fill[if_..if_ + 4]);
                if_ += 4;
            }
            if let Some(s) = &mut sh.stroke {
                s.color = rgba(&stroke[4 * is..4 * is + 4]);
                let w = width[is];
                s.width = if w.is_finite() { w.max(0.0) } else { 0.0 };
                is += 1;
            }
        }
        scene.background = rgba(bg);
        Ok(())
    }

    pub fn get(&self, g: ParamGroup) -> &[f32] {
        &self.groups[g.index()]
    }

    pub fn get_mut(&mut self, g: ParamGroup) -> &mut [f32] {
        &mut self.groups[g.index()]
    }

    /// Total number of scalars over all groups.
    pub fn len(&self) -> usize {
        self.groups.iter().map(Vec::len).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether every value is finite.
    pub fn all_finite(&self) -> bool {
        self.groups.iter().flatten().all(|v| v.is_finite())
    }

    /// Sets every value of the groups not in `mask` to zero (for masking gradients).
    pub fn mask(&mut self, mask: &Trainable) {
        for g in ParamGroup::ALL {
            if !mask.contains(g) {
                self.get_mut(g).fill(0.0);
            }
        }
    }

    /// `self += alpha * other`, group by group (layouts must match).
    pub fn add_scaled(&mut self, other: &Params, alpha: f32) {
        for (a, b) in self.groups.iter_mut().zip(&other.groups) {
            for (x, y) in a.iter_mut().zip(b) {
                *x += alpha * y;
            }
        }
    }

    /// Point-gradient offset of shape `index` in the `Points` group, in scalars.
    pub fn point_offset(scene: &Scene, index: usize) -> usize {
        2 * scene.shapes[..index]
            .iter()
            .map(|s| s.points.len())
            .sum::<usize>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Shape, Stroke};

    fn scene() -> Scene {
        let mut s = Scene::new(64, 64, Rgba::WHITE).unwrap();
        s.shapes
            .push(Shape::circle(20.0, 20.0, 5.0, 4, Rgba::new(1.0, 0.0, 0.0, 0.8)).unwrap());
        s.shapes.push(
            Shape::open_cubic(
                vec![Point::new(1.0, 2.0); 4],
                Stroke::round(Rgba::BLACK, 3.0),
            )
            .unwrap(),
        );
        s
    }

    #[test]
    fn round_trip_and_layout() {
        let s = scene();
        let p = Params::from_scene(&s);
        assert_eq!(p.get(ParamGroup::Points).len(), 2 * 16);
        assert_eq!(p.get(ParamGroup::Fill), &[1.0, 0.0, 0.0, 0.8]);
        assert_eq!(p.get(ParamGroup::Width), &[3.0]);
        let mut s2 = s.clone();
        let mut p2 = p.clone();
        p2.get_mut(ParamGroup::Points)[0] = 99.0;
        p2.get_mut(ParamGroup::Fill)[0] = 2.0; // clamped on write
        p2.write_to(&mut s2).unwrap();
        assert_eq!(s2.shapes[0].points[0].x, 99.0);
        assert_eq!(s2.shapes[0].fill.unwrap().r, 1.0);
        assert!(s2.validate().is_ok());
        assert_eq!(Params::point_offset(&s, 1), 24);
    }

    #[test]
    fn write_rejects_bad_layout_and_nan() {
        let mut s = scene();
        let mut p = Params::from_scene(&s);
        p.get_mut(ParamGroup::Points)[3] = f32::NAN;
        assert!(p.write_to(&mut s).is_err());
        assert_eq!(s, scene());
        let empty = Params::zeros_like(&Scene::new(8, 8, Rgba::WHITE).unwrap());
        assert!(matches!(
            empty.write_to(&mut s),
            Err(SceneError::ParamLength { .. })
        ));
    }

    #[test]
    fn mask_zeroes_frozen_groups() {
        let s = scene();
        let mut p = Params::from_scene(&s);
        p.mask(&Trainable {
            points: false,
            ..Trainable::ALL
        });
        assert!(p.get(ParamGroup::Points).iter().all(|v| *v == 0.0));
        assert_eq!(p.get(ParamGroup::Width), &[3.0]);
    }
}
