//! Gradient paint: forward values against the model, and every gradient parameter's
//! derivative against central finite differences (f64).

use super::tests::{fd_check, grad_f64, loss_f64};
use super::*;
use crate::scene::{
    Affine, Gradient, GradientGeometry, GradientStop, Gradients, Rgba, Spread, Stroke,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn stops(colors: &[(f32, [f32; 4])]) -> Vec<GradientStop> {
    colors
        .iter()
        .map(|&(offset, c)| GradientStop {
            offset,
            color: Rgba::from_array(c),
        })
        .collect()
}

pub(super) fn linear(x1: f32, y1: f32, x2: f32, y2: f32, spread: Spread) -> Gradient {
    Gradient {
        geometry: GradientGeometry::Linear { x1, y1, x2, y2 },
        transform: Affine::IDENTITY,
        spread,
        stops: stops(&[
            (0.1, [1.0, 0.0, 0.0, 1.0]),
            (0.5, [0.1, 0.8, 0.2, 0.6]),
            (0.8, [0.0, 0.2, 1.0, 0.9]),
        ]),
    }
}

pub(super) fn radial(spread: Spread, fr: f32) -> Gradient {
    Gradient {
        geometry: GradientGeometry::Radial {
            cx: 2.0,
            cy: 1.0,
            r: 5.5,
            fx: 1.0,
            fy: 0.2,
            fr,
        },
        // Rotated, scaled and moved: gradient space is not canvas space.
        transform: Affine([1.2, 0.5, -0.4, 0.9, 11.0, 9.0]),
        spread,
        // Offsets strictly inside (0, 1): a pad region then holds its colour away from the
        // kink at the end stop's offset.
        stops: stops(&[
            (0.02, [1.0, 1.0, 0.0, 1.0]),
            (0.3, [0.9, 0.1, 0.3, 0.8]),
            (0.97, [0.1, 0.1, 0.6, 1.0]),
        ]),
    }
}

pub(super) fn with(mut s: Shape, fill: Option<Gradient>, stroke: Option<Gradient>) -> Shape {
    s.gradients = Some(Box::new(Gradients {
        fill,
        stroke,
        texture: None,
    }));
    s
}

/// A filled linear, a filled-and-stroked radial and an open stroked linear gradient.
pub(super) fn scene(spread: Spread) -> Scene {
    let mut s = Scene::new(24, 20, Rgba::new(0.9, 0.9, 0.8, 1.0)).unwrap();
    let blob = Shape::circle(8.3, 9.1, 6.6, 4, Rgba::BLACK).unwrap();
    s.shapes.push(with(
        blob,
        Some(linear(3.07, 4.21, 14.03, 12.11, spread)),
        None,
    ));
    let mut disc = Shape::circle(14.2, 10.4, 7.3, 5, Rgba::BLACK).unwrap();
    disc.stroke = Some(Stroke::round(Rgba::BLACK, 1.5));
    let rs = radial(spread, 0.7);
    s.shapes.push(with(disc, Some(rs.clone()), Some(rs)));
    let line = Shape::open_cubic(
        Point::list(&[(1.0, 17.0), (8.0, 12.0), (15.0, 19.0), (22.5, 13.0)]),
        Stroke::round(Rgba::BLACK, 3.0),
    )
    .unwrap();
    s.shapes.push(with(
        line,
        None,
        Some(linear(2.13, 16.07, 12.21, 13.9, spread)),
    ));
    s.validate().unwrap();
    s
}

/// Checks every gradient parameter; returns (checked, mismatches).
pub(super) fn fd_check_paint(scene: &Scene, seed: u64) -> (usize, Vec<String>) {
    let sc = SceneT::<f64>::from_scene(scene, FLATTEN_TOLERANCE);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = 4 * (scene.width * scene.height) as usize;
    let w: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let an = grad_f64(&sc, &w).paint;
    let mut bad = Vec::new();
    let mut k0 = 0;
    for pi in 0..sc.paints.len() {
        for k in 0..sc.paints[pi].num_params() {
            let h = 1e-6;
            let mut p = sc.clone();
            *p.paints[pi].param_mut(k) += h;
            let lp = loss_f64(&p, &w);
            *p.paints[pi].param_mut(k) -= 2.0 * h;
            let lm = loss_f64(&p, &w);
            let fd = (lp - lm) / (2.0 * h);
            let a = an[k0 + k];
            assert!(a.is_finite(), "paint {pi}[{k}] not finite");
            if (fd - a).abs() > 1e-3 * (1.0 + fd.abs().max(a.abs())) {
                bad.push(format!("paint {pi}[{k}]: analytic {a:.6} fd {fd:.6}"));
            }
        }
        k0 += sc.paints[pi].num_params();
    }
    (k0, bad)
}

#[test]
fn gradient_parameters_match_finite_differences() {
    for (i, spread) in [Spread::Pad, Spread::Reflect, Spread::Repeat]
        .into_iter()
        .enumerate()
    {
        let s = scene(spread);
        let (checked, bad) = fd_check_paint(&s, 40 + i as u64);
        assert_eq!(
            checked,
            crate::scene::paint::scene_gradient_params(&s).len()
        );
        // Repeat and reflect jump or kink where t crosses an integer at a pixel centre.
        assert!(
            bad.len() * 50 <= checked,
            "{spread:?}: {} of {checked} mismatched:\n{}",
            bad.len(),
            bad.join("\n")
        );
        // Geometry, offsets and colours all get non-zero gradients.
        let sc = SceneT::<f64>::from_scene(&s, FLATTEN_TOLERANCE);
        let w = vec![1.0; 4 * 24 * 20];
        let g = grad_f64(&sc, &w).paint;
        assert!(
            g[..4].iter().all(|v| *v != 0.0),
            "{spread:?}: linear geometry {g:?}"
        );
        assert!(
            g[5] != 0.0 && g[4] != 0.0,
            "{spread:?}: offset / colour {g:?}"
        );
    }
}

#[test]
fn shapes_and_flat_parameters_keep_exact_gradients_under_gradient_paint() {
    let s = scene(Spread::Pad);
    let (checked, bad) = fd_check(&s, 9);
    assert!(bad.len() * 50 <= checked, "{}", bad.join("\n"));
    // The flat stand-in colours are not painted: their gradients are zero.
    let (_, tape) = render_tape(&s);
    let d = vec![1.0f32; 4 * 24 * 20];
    let (g, gp) = backward_with_gradients(&s, &tape, &d);
    assert!(g.get(ParamGroup::Fill).iter().all(|v| *v == 0.0));
    assert!(g.get(ParamGroup::Points).iter().any(|v| *v != 0.0));
    assert_eq!(
        gp.len(),
        crate::scene::paint::scene_gradient_params(&s).len()
    );
}

#[test]
fn linear_gradient_colours_follow_the_stops() {
    let mut s = Scene::new(20, 4, Rgba::TRANSPARENT).unwrap();
    let rect = Shape::polygon(
        Point::list(&[(0.0, 0.0), (20.0, 0.0), (20.0, 4.0), (0.0, 4.0)]),
        Rgba::BLACK,
    )
    .unwrap();
    let mut g = linear(0.0, 0.0, 20.0, 0.0, Spread::Pad);
    g.stops = stops(&[(0.25, [1.0, 0.0, 0.0, 1.0]), (0.75, [0.0, 0.0, 1.0, 1.0])]);
    s.shapes.push(with(rect, Some(g), None));
    let im = render(&s);
    // Pixel centres 0.5..19.5: red before x = 5, blue after x = 15, halfway at x = 10.
    assert_eq!(im.pixel(2, 1), [1.0, 0.0, 0.0, 1.0]);
    assert_eq!(im.pixel(17, 1), [0.0, 0.0, 1.0, 1.0]);
    let mid = im.pixel(9, 1);
    assert!(
        (mid[0] - 0.55).abs() < 1e-5 && (mid[2] - 0.45).abs() < 1e-5,
        "{mid:?}"
    );
}

#[test]
fn radial_spread_methods_repeat_and_mirror() {
    let mut g = radial(Spread::Repeat, 0.0);
    g.geometry = GradientGeometry::Radial {
        cx: 0.0,
        cy: 0.0,
        r: 4.0,
        fx: 0.0,
        fy: 0.0,
        fr: 0.0,
    };
    g.transform = Affine([1.0, 0.0, 0.0, 1.0, 0.5, 0.5]);
    let t_of = |spread: Spread, x: i32| {
        let p = paint::PaintT::<f64>::of(&Gradient {
            spread,
            ..g.clone()
        });
        let sh = paint::GradientShade::new(&p);
        paint::Shade::color(&sh, x, 0)
    };
    // Centre (x + 0.5) maps to distance x; t = x / 4.
    for x in [1, 5, 9] {
        let (pad, rep, refl) = (
            t_of(Spread::Pad, x),
            t_of(Spread::Repeat, x),
            t_of(Spread::Reflect, x),
        );
        let base = t_of(Spread::Pad, x % 4);
        if x > 4 {
            assert_eq!(pad, t_of(Spread::Pad, 4), "pad holds the last stop");
            assert_eq!(rep, base, "repeat at {x}");
        }
        if x == 5 {
            assert_eq!(refl, t_of(Spread::Pad, 3), "reflect mirrors");
        }
    }
}
