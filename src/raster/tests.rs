use super::*;
use crate::scene::Rgba;

fn square_scene(x: f32, y: f32, side: f32) -> Scene {
    let mut s = Scene::new(16, 16, Rgba::TRANSPARENT).unwrap();
    s.shapes
        .push(Shape::square(x, y, side, Rgba::new(1.0, 0.0, 0.0, 1.0)).unwrap());
    s
}

#[test]
fn square_coverage_is_exact_area() {
    let im = render(&square_scene(2.25, 3.5, 4.0));
    // Column 2 is covered 0.75 horizontally; row 3 covered 0.5 vertically.
    assert!(
        (im.pixel(2, 3)[3] - 0.375).abs() < 1e-5,
        "{:?}",
        im.pixel(2, 3)
    );
    assert!((im.pixel(3, 4)[3] - 1.0).abs() < 1e-6);
    assert!((im.pixel(6, 4)[3] - 0.25).abs() < 1e-5);
    assert_eq!(im.pixel(7, 4)[3], 0.0);
    assert_eq!(im.pixel(3, 8)[3], 0.0);
    let total: f32 = im.data.chunks(4).map(|p| p[3]).sum();
    assert!((total - 16.0).abs() < 1e-4, "{total}");
}

// ---------------------------------------------------------------------------------------------
// Finite-difference gradient checks (f64).

use super::engine;
use super::geom;
use super::grad::GradT;
use crate::scene::{Point, Stroke};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub(super) fn loss_f64(sc: &SceneT<f64>, w: &[f64]) -> f64 {
    render_t(sc).iter().zip(w).map(|(a, b)| a * b).sum()
}

pub(super) fn grad_f64(sc: &SceneT<f64>, w: &[f64]) -> GradT<f64> {
    let ls = geom::layers(sc);
    let (_, tapes) = engine::forward(sc, &ls, true, Vec::new());
    engine::backward(sc, &ls, &tapes, w)
}

/// Mutable reference to parameter `k` of group `g` (Params layout).
fn param(sc: &mut SceneT<f64>, g: ParamGroup, k: usize) -> &mut f64 {
    let mut k = k;
    match g {
        ParamGroup::Background => &mut sc.bg[k],
        ParamGroup::Opacity => &mut sc.groups[k].opacity,
        _ => {
            for s in &mut sc.shapes {
                let n = match g {
                    ParamGroup::Points => 2 * s.pts.len(),
                    ParamGroup::Fill => 4 * s.fill.is_some() as usize,
                    ParamGroup::Stroke => 4 * s.stroke.is_some() as usize,
                    _ => s.stroke.is_some() as usize,
                };
                if k < n {
                    return match g {
                        ParamGroup::Points => &mut s.pts[k / 2][k % 2],
                        ParamGroup::Fill => &mut s.fill.as_mut().unwrap()[k],
                        ParamGroup::Stroke => &mut s.stroke.as_mut().unwrap().0[k],
                        _ => &mut s.stroke.as_mut().unwrap().1,
                    };
                }
                k -= n;
            }
            unreachable!("parameter index out of range")
        }
    }
}

fn group(g: &GradT<f64>, grp: ParamGroup) -> &[f64] {
    match grp {
        ParamGroup::Points => &g.points,
        ParamGroup::Fill => &g.fill,
        ParamGroup::Stroke => &g.stroke,
        ParamGroup::Width => &g.width,
        ParamGroup::Background => &g.bg,
        ParamGroup::Opacity => &g.opacity,
        // Checked through `GradT::paint` by the paint tests.
        ParamGroup::PaintGeometry | ParamGroup::PaintStops => &[],
    }
}

/// Checks every parameter; returns (checked, mismatches, worst message).
pub(super) fn fd_check(scene: &Scene, seed: u64) -> (usize, Vec<String>) {
    scene.validate().unwrap();
    let sc = SceneT::<f64>::from_scene(scene, FLATTEN_TOLERANCE);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = 4 * (scene.width * scene.height) as usize;
    let w: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let an = grad_f64(&sc, &w);
    let mut bad = Vec::new();
    let mut checked = 0;
    for grp in ParamGroup::ALL {
        for k in 0..group(&an, grp).len() {
            let h = if grp == ParamGroup::Points || grp == ParamGroup::Width {
                1e-5
            } else {
                1e-6
            };
            let mut p = sc.clone();
            *param(&mut p, grp, k) += h;
            let lp = loss_f64(&p, &w);
            *param(&mut p, grp, k) -= 2.0 * h;
            let lm = loss_f64(&p, &w);
            let fd = (lp - lm) / (2.0 * h);
            let a = group(&an, grp)[k];
            assert!(a.is_finite(), "{grp:?}[{k}] not finite");
            checked += 1;
            if (fd - a).abs() > 1e-3 * (1.0 + fd.abs().max(a.abs())) {
                bad.push(format!("{grp:?}[{k}]: analytic {a:.6} fd {fd:.6}"));
            }
        }
    }
    (checked, bad)
}

pub(super) fn rgba(rng: &mut ChaCha8Rng) -> Rgba {
    Rgba::new(
        rng.random_range(0.0..1.0),
        rng.random_range(0.0..1.0),
        rng.random_range(0.0..1.0),
        rng.random_range(0.3..1.0),
    )
}

pub(super) fn random_scene(seed: u64) -> Scene {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (w, h) = (24u32, 20u32);
    let bg = rgba(&mut rng);
    let mut s = Scene::new(w, h, bg).unwrap();
    let pt = |rng: &mut ChaCha8Rng, lo: f32, hi: f32| {
        Point::new(rng.random_range(lo..hi), rng.random_range(lo..hi * 0.85))
    };
    // Random closed cubics: control points anywhere (self-intersecting), some off canvas.
    for _ in 0..2 {
        let pts = (0..9).map(|_| pt(&mut rng, -6.0, 30.0)).collect();
        s.shapes
            .push(Shape::closed_cubic(pts, rgba(&mut rng)).unwrap());
    }
    // Circle-ish blob.
    s.shapes
        .push(Shape::circle(12.3, 9.7, 6.1, 4, rgba(&mut rng)).unwrap());
    // Tiny path.
    s.shapes
        .push(Shape::circle(5.3, 14.2, 0.35, 3, rgba(&mut rng)).unwrap());
    // Polygon with a stroke.
    let mut poly = Shape::polygon(
        (0..5).map(|_| pt(&mut rng, 0.0, 24.0)).collect(),
        rgba(&mut rng),
    )
    .unwrap();
    poly.stroke = Some(Stroke::round(rgba(&mut rng), 1.7));
    s.shapes.push(poly);
    // Open strokes: thin, thick, partly off canvas.
    for wdt in [0.6f32, 2.5, 4.0] {
        let pts = (0..7).map(|_| pt(&mut rng, -4.0, 28.0)).collect();
        s.shapes
            .push(Shape::open_cubic(pts, Stroke::round(rgba(&mut rng), wdt)).unwrap());
    }
    s
}

/// [`fd_check`] on `scene`, failing when more than 1 in 50 parameters disagree. Central
/// differences straddle the kinks of the coverage (`min(|A|, 1)`, the even-odd fold) and of the
/// stroke profile in a handful of parameters; everything else must agree to 1e-3 relative.
pub(super) fn assert_fd(scene: &Scene, seed: u64) {
    let (checked, bad) = fd_check(scene, seed);
    assert!(
        bad.len() * 50 <= checked,
        "seed {seed}: {} of {checked} mismatched:\n{}",
        bad.len(),
        bad.join("\n")
    );
    eprintln!(
        "seed {seed}: {checked} params, {} kink mismatches {:?}",
        bad.len(),
        bad
    );
}

#[test]
fn gradients_match_finite_differences_on_random_scenes() {
    for seed in 0..4 {
        assert_fd(&random_scene(seed), 100 + seed);
    }
}

#[test]
fn degenerate_scenes_have_finite_gradients() {
    let mut s = Scene::new(12, 10, Rgba::new(0.2, 0.3, 0.4, 0.5)).unwrap();
    let p = Point::new(4.37, 5.21);
    s.shapes
        .push(Shape::closed_cubic(vec![p; 6], Rgba::new(1.0, 0.0, 0.0, 1.0)).unwrap());
    s.shapes
        .push(Shape::open_cubic(vec![p; 4], Stroke::round(Rgba::BLACK, 2.0)).unwrap());
    s.shapes.push(
        Shape::open_cubic(
            vec![Point::new(1.0, 1.0); 4],
            Stroke::round(Rgba::BLACK, 0.0),
        )
        .unwrap(),
    );
    // Entirely off canvas.
    s.shapes
        .push(Shape::circle(-50.0, 200.0, 5.0, 4, Rgba::BLACK).unwrap());
    let (img, tape) = render_tape(&s);
    assert!(
        img.data
            .iter()
            .all(|v| v.is_finite() && (0.0..=1.0).contains(v))
    );
    let d = vec![1.0f32; img.data.len()];
    let g = backward(&s, &tape, &d);
    assert!(g.all_finite());
    // A zero-length stroke still draws a round dot of the given width and has gradients.
    assert!(img.pixel(4, 4)[3] > 0.5);
    assert!(g.get(ParamGroup::Width)[0] > 0.0, "dot grows with width");
    // f64 check on the degenerate scene as well.
    let (checked, bad) = fd_check(&s, 7);
    assert!(bad.len() * 20 <= checked, "{bad:?}");
}

#[test]
fn f32_backward_matches_f64() {
    let s = random_scene(9);
    let sc = SceneT::<f64>::from_scene(&s, FLATTEN_TOLERANCE);
    let n = 4 * (s.width * s.height) as usize;
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let w: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let g64 = grad_f64(&sc, &w);
    let (_, tape) = render_tape(&s);
    let w32: Vec<f32> = w.iter().map(|v| *v as f32).collect();
    let g32 = backward(&s, &tape, &w32);
    for grp in ParamGroup::ALL {
        for (a, b) in g32.get(grp).iter().zip(group(&g64, grp)) {
            assert!(
                (*a as f64 - b).abs() <= 1e-3 * (1.0 + b.abs()),
                "{grp:?}: {a} vs {b}"
            );
        }
    }
}

#[test]
fn backward_rejects_mismatched_tape_without_panicking() {
    let s = random_scene(1);
    let (_, tape) = render_tape(&s);
    let other = square_scene(1.0, 1.0, 3.0);
    let g = backward(&other, &tape, &vec![1.0; 4 * 16 * 16]);
    assert_eq!(g, Params::zeros_like(&other));
    let g = backward(&s, &tape, &[1.0; 3]);
    assert!(g.get(ParamGroup::Points).iter().all(|v| *v == 0.0));
}

#[test]
fn flatten_shape_follows_the_curve_within_tolerance() {
    let c = Shape::circle(50.0, 40.0, 30.0, 4, Rgba::BLACK).unwrap();
    for tol in [0.5f32, 0.05] {
        let polys = flatten_shape(&c, tol);
        assert_eq!(polys.len(), 1);
        let p = &polys[0];
        assert!(p.len() >= 8);
        // Vertices lie on the (cubic approximation of the) circle; chord midpoints are within
        // tolerance (plus the cubic's own 0.03% radial error).
        for (i, v) in p.iter().enumerate() {
            let r = ((v.x - 50.0).powi(2) + (v.y - 40.0).powi(2)).sqrt();
            assert!((r - 30.0).abs() < 0.02, "vertex radius {r}");
            let w = p[(i + 1) % p.len()];
            let m = Point::new(0.5 * (v.x + w.x), 0.5 * (v.y + w.y));
            let rm = ((m.x - 50.0).powi(2) + (m.y - 40.0).powi(2)).sqrt();
            assert!(30.0 - rm < tol + 0.02, "chord sag {} > {tol}", 30.0 - rm);
        }
    }
    assert!(flatten_shape(&c, 0.05)[0].len() > flatten_shape(&c, 0.5)[0].len());
    let sq = Shape::square(1.0, 2.0, 3.0, Rgba::BLACK).unwrap();
    assert_eq!(flatten_shape(&sq, 0.1)[0], sq.points);
}

#[test]
fn stroke_area_is_length_times_width_plus_caps() {
    let mut s = Scene::new(64, 32, Rgba::TRANSPARENT).unwrap();
    s.shapes.push(
        Shape::open_cubic(
            Point::list(&[(10.0, 16.0), (20.0, 16.0), (40.0, 16.0), (50.0, 16.0)]),
            Stroke::round(Rgba::BLACK, 4.0),
        )
        .unwrap(),
    );
    let total: f32 = render(&s).data.chunks(4).map(|p| p[3]).sum();
    let expected = 40.0 * 4.0 + std::f32::consts::PI * 4.0;
    assert!(
        (total - expected).abs() < 0.02 * expected,
        "{total} vs {expected}"
    );
    // Thin strokes keep their area too (no double counting at joins).
    s.shapes[0].stroke.as_mut().unwrap().width = 0.5;
    let total: f32 = render(&s).data.chunks(4).map(|p| p[3]).sum();
    let expected = 40.0 * 0.5;
    assert!(
        (total - expected).abs() < 0.05 * expected,
        "{total} vs {expected}"
    );
}

#[test]
fn render_is_deterministic_and_independent_of_thread_count() {
    let s = random_scene(5);
    let a = render(&s);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let b = pool.install(|| render(&s));
    assert_eq!(a, render(&s));
    assert_same_image(&a, &b);
}

/// Fails unless `a` and `b` agree to 1e-5 in every channel.
pub(super) fn assert_same_image(a: &Image, b: &Image) {
    let max = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max);
    assert!(max < 1e-5, "{max}");
}

/// The weighted L2 of `s`'s render against a random target (weights and target from `seed`):
/// by render-then-backward and by the fused pass, each as (loss, gradients, gradient-paint
/// gradients).
pub(super) fn separate_and_fused(s: &Scene, seed: u64) -> [(f64, Params, Vec<f32>); 2] {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = (s.width * s.height) as usize;
    let target = Image {
        width: s.width,
        height: s.height,
        data: (0..4 * n).map(|_| rng.random_range(0.0..1.0f32)).collect(),
    };
    let w: Vec<f32> = (0..n).map(|_| rng.random_range(0.0..2.0f32)).collect();
    let (img, tape) = render_tape(s);
    let mut d = Vec::new();
    let want_loss = crate::losses::weighted_l2_into(&img, &target, &w, &mut d).unwrap();
    let (want, want_paint) = backward_with_gradients(s, &tape, &d);
    let band = |px: std::ops::Range<usize>, img: &[f32], g: &mut [f32]| {
        let t = &target.data[4 * px.start..4 * px.end];
        crate::losses::weighted_l2_slices(img, t, &w[px], g)
    };
    let (loss, got) = render_loss_backward(s, &band);
    let sc = SceneT::<f32>::from_scene(s, FLATTEN_TOLERANCE);
    let (_, g, _) = engine::forward_backward(&sc, &geom::layers(&sc), Vec::new(), &band);
    [(want_loss, want, want_paint), (loss, got, g.paint)]
}

#[test]
fn fused_loss_pass_matches_render_then_backward() {
    // 24x20 (two bands) and 96x80 (several bands), a non-uniform target and weights.
    for (seed, width) in [(0u64, 24u32), (1, 24), (2, 96)] {
        let s = random_scene(seed).scaled_to_width(width);
        let [(want_loss, want, _), (loss, got, _)] = separate_and_fused(&s, seed + 100);
        assert_eq!(got, want, "seed {seed}: the same gradients, bit for bit");
        assert!(got.get(ParamGroup::Points).iter().any(|v| *v != 0.0));
        let rel = (loss - want_loss).abs() / want_loss.abs();
        assert!(rel < 1e-6, "seed {seed}: loss {loss} vs {want_loss}");
    }
}

#[test]
fn recorded_pieces_give_the_walks_deposit_and_gradient_bit_for_bit() {
    use super::walk::{Clip, deposit, deposit_record, edge_grad, edge_grad_recorded};
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let clip = Clip {
        x0: 2,
        x1: 13,
        y0: 3,
        y1: 11,
    };
    let (cw, rows) = (11usize, 8usize);
    let g: Vec<f32> = (0..cw * rows)
        .map(|i| {
            if i % 5 == 0 {
                0.0
            } else {
                rng.random_range(-1.0..1.0)
            }
        })
        .collect();
    let point = |rng: &mut ChaCha8Rng| [rng.random_range(-2.0..16.0), rng.random_range(0.0..14.0)];
    for k in 0..300 {
        let p0 = point(&mut rng);
        // Some horizontal and vertical edges too.
        let p1 = match k % 10 {
            0 => [rng.random_range(-2.0..16.0), p0[1]],
            1 => [p0[0], rng.random_range(0.0..14.0)],
            _ => point(&mut rng),
        };
        let (mut a, mut b) = (vec![0.0f32; (cw + 1) * rows], vec![0.0f32; (cw + 1) * rows]);
        deposit(p0, p1, clip, &mut a, cw + 1);
        let mut pieces = Vec::new();
        deposit_record(p0, p1, clip, &mut b, &mut pieces);
        assert!(
            a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()),
            "{p0:?} {p1:?}"
        );
        let (mut d0, mut d1, mut e0, mut e1) = ([0.0f32; 2], [0.0; 2], [0.0; 2], [0.0; 2]);
        edge_grad(p0, p1, clip, &g, cw, &mut d0, &mut d1);
        edge_grad_recorded(p0, p1, &pieces, &g, &mut e0, &mut e1);
        let bits = |v: [f32; 2]| v.map(f32::to_bits);
        assert_eq!((bits(d0), bits(d1)), (bits(e0), bits(e1)), "{p0:?} {p1:?}");
    }
}

#[test]
fn row_renders_are_the_whole_renders_rows_bit_for_bit() {
    // 96x80: several row bands; ranges inside one band, across bands, at the edges and past them.
    for seed in 0..3u64 {
        let s = random_scene(seed).scaled_to_width(96);
        let whole = render(&s);
        let row = 4 * s.width as usize;
        for rows in [0..1, 3..9, 17..50, 70..80, 79..200, 0..80] {
            let (first, data) = render_rows(&s, rows.clone());
            assert!(
                first <= rows.start,
                "seed {seed} {rows:?}: starts at {first}"
            );
            assert!(first as usize * row + data.len() >= rows.end.min(80) as usize * row);
            let at = first as usize * row;
            assert!(
                data == whole.data[at..at + data.len()],
                "seed {seed} {rows:?}: not the whole render's rows"
            );
        }
        assert!(render_rows(&s, 5..5).1.is_empty());
        assert!(render_rows(&s, 80..90).1.is_empty());
        // Removing a shape changes no pixel outside its rows.
        let rows = shape_rows(&s);
        assert_eq!(rows.len(), s.shapes.len());
        for (i, r) in rows.iter().enumerate() {
            let mut trial = s.clone();
            trial.remove_shape(i);
            let after = render(&trial);
            for y in (0..80usize).filter(|y| !r.contains(&(*y as u32))) {
                assert!(
                    after.data[y * row..(y + 1) * row] == whole.data[y * row..(y + 1) * row],
                    "seed {seed}: removing shape {i} ({r:?}) changed row {y}"
                );
            }
        }
        // The random scene's shapes reach into the canvas.
        assert!(rows.iter().filter(|r| !r.is_empty()).count() >= 5);
    }
}
