//! The flat parameter view of a [`Scene`]: one `Vec<f32>` per [`ParamGroup`], in shape order.
//!
//! Layout (all in shape order, skipping shapes that lack the attribute):
//! - `Points`: `x, y` for every point of every shape.
//! - `Fill`: `r, g, b, a` for every shape with a fill.
//! - `Stroke`: `r, g, b, a` for every shape with a stroke.
//! - `Width`: one stroke width for every shape with a stroke.
//! - `Background`: `r, g, b, a`.
//! - `Opacity`: the opacity of every group of [`Scene::groups`] (empty for a flat scene); trained
//!   with the fill colours ([`Trainable::fill`]).
//! - `PaintGeometry`: every gradient paint's geometry (`x1, y1, x2, y2` or `cx, cy, r, fx, fy,
//!   fr`, pixels of gradient space), shape by shape, fill before stroke.
//! - `PaintStops`: every gradient paint's `offset, r, g, b, a` per stop, in the same order.
//!
//! The two paint groups split [`crate::scene::paint::scene_gradient_params`] by unit (pixels
//! and `[0, 1]`) so each gets a learning rate of its own.
//!
//! Gradients from the rasteriser use the same type and layout, so an optimiser can walk the
//! groups of parameters and gradients side by side.

use super::paint::{Gradient, scene_gradient_params, write_scene_gradient_params};
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
    Opacity,
    PaintGeometry,
    PaintStops,
}

impl ParamGroup {
    pub const ALL: [ParamGroup; 8] = [
        ParamGroup::Points,
        ParamGroup::Fill,
        ParamGroup::Stroke,
        ParamGroup::Width,
        ParamGroup::Background,
        ParamGroup::Opacity,
        ParamGroup::PaintGeometry,
        ParamGroup::PaintStops,
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
    /// Gradient paints: geometry and stops (`false` in settings stored before it existed).
    #[serde(default)]
    pub paint: bool,
}

impl Trainable {
    pub const ALL: Trainable = Trainable {
        points: true,
        fill: true,
        stroke: true,
        width: true,
        background: true,
        paint: true,
    };
    pub const NONE: Trainable = Trainable {
        points: false,
        fill: false,
        stroke: false,
        width: false,
        background: false,
        paint: false,
    };

    pub fn contains(&self, g: ParamGroup) -> bool {
        match g {
            ParamGroup::Points => self.points,
            ParamGroup::Fill | ParamGroup::Opacity => self.fill,
            ParamGroup::Stroke => self.stroke,
            ParamGroup::Width => self.width,
            ParamGroup::Background => self.background,
            ParamGroup::PaintGeometry | ParamGroup::PaintStops => self.paint,
        }
    }
}

/// Flat parameters (or gradients) of a scene, one vector per group.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Params {
    #[serde(deserialize_with = "groups_or_flat_only")]
    groups: [Vec<f32>; 8],
}

/// The groups as serialized, or the first five alone (`Points` .. `Background`), as checkpoints
/// stored before groups and gradient paints were written them: those scenes had neither, so the
/// missing groups are empty and an interrupted job resumes where it stopped.
fn groups_or_flat_only<'de, D: serde::Deserializer<'de>>(d: D) -> Result<[Vec<f32>; 8], D::Error> {
    let stored = Vec::<Vec<f32>>::deserialize(d)?;
    if stored.len() != 5 && stored.len() != ParamGroup::ALL.len() {
        return Err(serde::de::Error::invalid_length(
            stored.len(),
            &"5 or 8 parameter groups",
        ));
    }
    let mut groups: [Vec<f32>; 8] = Default::default();
    for (g, s) in groups.iter_mut().zip(stored) {
        *g = s;
    }
    Ok(groups)
}

impl Params {
    /// All-zero parameters with the layout of `scene` (the shape of a gradient).
    pub fn zeros_like(scene: &Scene) -> Self {
        let n_points = scene.num_points();
        let n_fill = scene.shapes.iter().filter(|s| s.fill.is_some()).count();
        let n_stroke = scene.shapes.iter().filter(|s| s.stroke.is_some()).count();
        let (n_geometry, n_stops) = paint_gradients(scene)
            .map(|g| (g.geometry.values().len(), 5 * g.stops.len()))
            .fold((0, 0), |(a, b), (x, y)| (a + x, b + y));
        Params {
            groups: [
                vec![0.0; 2 * n_points],
                vec![0.0; 4 * n_fill],
                vec![0.0; 4 * n_stroke],
                vec![0.0; n_stroke],
                vec![0.0; 4],
                vec![0.0; scene.groups.len()],
                vec![0.0; n_geometry],
                vec![0.0; n_stops],
            ],
        }
    }

    /// Reads the parameters out of `scene`.
    pub fn from_scene(scene: &Scene) -> Self {
        let mut p = Params::zeros_like(scene);
        p.set_paint(scene, &scene_gradient_params(scene));
        let [pts, fill, stroke, width, bg, opacity, ..] = &mut p.groups;
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
        for (o, g) in opacity.iter_mut().zip(&scene.groups) {
            *o = g.opacity;
        }
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
        let [pts, fill, stroke, width, bg, opacity, ..] = &self.groups;
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
        for (g, &o) in scene.groups.iter_mut().zip(opacity) {
            g.opacity = if o.is_nan() { 0.0 } else { o.clamp(0.0, 1.0) };
        }
        write_scene_gradient_params(scene, &self.paint(scene)).map_err(|reason| SceneError::Shape {
            shape: usize::MAX,
            reason,
        })
    }

    /// The two paint groups joined back into [`scene_gradient_params`] order (layouts must
    /// match `scene`'s).
    pub fn paint(&self, scene: &Scene) -> Vec<f32> {
        let (geo, stops) = (
            self.get(ParamGroup::PaintGeometry),
            self.get(ParamGroup::PaintStops),
        );
        let mut out = Vec::with_capacity(geo.len() + stops.len());
        let (mut ig, mut is) = (0, 0);
        for g in paint_gradients(scene) {
            let (ng, ns) = (g.geometry.values().len(), 5 * g.stops.len());
            out.extend_from_slice(&geo[ig..ig + ng]);
            out.extend_from_slice(&stops[is..is + ns]);
            ig += ng;
            is += ns;
        }
        out
    }

    /// Splits `flat` ([`scene_gradient_params`] order, e.g. the rasteriser's paint gradients)
    /// into the two paint groups (layouts must match `scene`'s).
    pub fn set_paint(&mut self, scene: &Scene, flat: &[f32]) {
        let [.., geo, stops] = &mut self.groups;
        let (mut k, mut ig, mut is) = (0, 0, 0);
        for g in paint_gradients(scene) {
            let (ng, ns) = (g.geometry.values().len(), 5 * g.stops.len());
            geo[ig..ig + ng].copy_from_slice(&flat[k..k + ng]);
            stops[is..is + ns].copy_from_slice(&flat[k + ng..k + ng + ns]);
            (k, ig, is) = (k + ng + ns, ig + ng, is + ns);
        }
    }

    /// Offsets (in scalars) of shape `index`'s first gradient in the two paint groups.
    pub fn paint_offset(scene: &Scene, index: usize) -> (usize, usize) {
        scene.shapes[..index]
            .iter()
            .filter_map(|s| s.gradients.as_deref())
            .flat_map(|g| g.iter())
            .fold((0, 0), |(a, b), g| {
                (a + g.geometry.values().len(), b + 5 * g.stops.len())
            })
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

/// Every gradient of `scene`, shape by shape, fill before stroke.
fn paint_gradients(scene: &Scene) -> impl Iterator<Item = &Gradient> {
    scene
        .shapes
        .iter()
        .filter_map(|s| s.gradients.as_deref())
        .flat_map(|g| g.iter())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Shape, Stroke};

    #[test]
    fn checkpoints_with_the_five_flat_groups_still_load() {
        let old = r#"{"groups":[[1.0,2.0],[0.5,0.5,0.5,1.0],[],[],[1.0,1.0,1.0,1.0]]}"#;
        let p: Params = serde_json::from_str(old).unwrap();
        assert_eq!(p.get(ParamGroup::Points), &[1.0, 2.0]);
        assert_eq!(p.get(ParamGroup::Background), &[1.0; 4]);
        assert!(p.get(ParamGroup::Opacity).is_empty());
        assert!(p.get(ParamGroup::PaintStops).is_empty());
        let back: Params = serde_json::from_str(&serde_json::to_string(&p).unwrap()).unwrap();
        assert_eq!(back, p);
        let six = r#"{"groups":[[],[],[],[],[],[]]}"#;
        assert!(serde_json::from_str::<Params>(six).is_err());
    }

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

    fn gradient_scene() -> Scene {
        let mut s = scene();
        crate::vector::fill::FillKind::Linear.paint_new(&mut s);
        s
    }

    #[test]
    fn paint_groups_round_trip() {
        let mut s = gradient_scene();
        let p = Params::from_scene(&s);
        assert_eq!(p.get(ParamGroup::PaintGeometry).len(), 4);
        assert_eq!(p.get(ParamGroup::PaintStops).len(), 10);
        assert_eq!(p.paint(&s), scene_gradient_params(&s));
        let mut p2 = p.clone();
        // Second stop: offset 1, colour green.
        p2.get_mut(ParamGroup::PaintStops)[5..10].copy_from_slice(&[1.0, 0.0, 1.0, 0.0, 1.0]);
        p2.get_mut(ParamGroup::PaintGeometry)[3] += 2.0;
        p2.write_to(&mut s).unwrap();
        let g = crate::vector::fill::fill_gradient(&s.shapes[0]).unwrap();
        assert_eq!(g.stops[1].color, Rgba::new(0.0, 1.0, 0.0, 1.0));
        // The flat stand-in follows the gradient (the mean of the stops).
        assert_eq!(s.shapes[0].fill.unwrap().g, 0.5);
        assert_eq!(Params::from_scene(&s), {
            let mut q = p2.clone();
            q.get_mut(ParamGroup::Fill)
                .copy_from_slice(&s.shapes[0].fill.unwrap().to_array());
            q
        });
        assert_eq!(Params::paint_offset(&s, 1), (4, 10));
        assert!(s.validate().is_ok());
    }

    /// Adam on the paint groups alone moves a flat-equivalent gradient toward a two-colour
    /// target drawn by the same shape: the loss falls.
    #[test]
    fn optimising_paint_lowers_the_loss() {
        use crate::optim::{Adam, AdamConfig, GroupSchedules, LrSchedule};
        let mut target_scene = gradient_scene();
        let mut tp = Params::from_scene(&target_scene);
        tp.get_mut(ParamGroup::PaintStops)[1..4].copy_from_slice(&[0.0, 0.0, 1.0]);
        tp.write_to(&mut target_scene).unwrap();
        let target = crate::raster::render(&target_scene);
        let mut s = gradient_scene();
        let loss_grad = |s: &Scene| {
            let (img, tape) = crate::raster::render_tape(s);
            let d: Vec<f32> = img
                .data
                .iter()
                .zip(&target.data)
                .map(|(a, b)| 2.0 * (a - b))
                .collect();
            let loss: f32 = img
                .data
                .iter()
                .zip(&target.data)
                .map(|(a, b)| (a - b) * (a - b))
                .sum();
            (loss, crate::raster::backward(s, &tape, &d))
        };
        let c = LrSchedule::Constant { lr: 0.05 };
        let z = LrSchedule::zero();
        let sched = GroupSchedules {
            points: z.clone(),
            fill: z.clone(),
            stroke: z.clone(),
            width: z.clone(),
            background: z,
            paint_geometry: LrSchedule::Constant { lr: 0.5 },
            paint_stops: c,
        };
        let only_paint = Trainable {
            paint: true,
            ..Trainable::NONE
        };
        let mut p = Params::from_scene(&s);
        let mut adam = Adam::new(&p, AdamConfig::default(), sched, only_paint);
        let (first, g) = loss_grad(&s);
        assert!(g.get(ParamGroup::PaintStops).iter().any(|v| *v != 0.0));
        assert!(g.get(ParamGroup::Fill)[..4].iter().all(|v| *v == 0.0));
        let mut last = first;
        for _ in 0..40 {
            let (l, g) = loss_grad(&s);
            last = l;
            adam.step(&mut p, &g);
            p.write_to(&mut s).unwrap();
        }
        assert!(last < 0.5 * first, "{first} -> {last}");
    }
}
