//! Butt and square caps, miter and bevel joins: coverage where SVG puts it, and gradients that
//! match finite differences.
use super::tests::fd_check;
use super::*;
use crate::scene::{LineCap, LineJoin, Rgba, Stroke};

fn styled(cap: LineCap, join: LineJoin, miter_limit: f32, width: f32) -> Stroke {
    Stroke {
        cap,
        join,
        miter_limit,
        ..Stroke::round(Rgba::new(0.1, 0.5, 0.9, 0.8), width)
    }
}

/// An open path of straight cubic segments through `pts`.
fn polyline(pts: &[(f32, f32)], st: Stroke) -> Shape {
    let mut out = vec![Point::new(pts[0].0, pts[0].1)];
    for w in pts.windows(2) {
        let (a, b) = (w[0], w[1]);
        let l = |t: f32| Point::new(a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
        out.extend([l(1.0 / 3.0), l(2.0 / 3.0), l(1.0)]);
    }
    Shape::open_cubic(out, st).unwrap()
}

fn alpha_sum(scene: &Scene) -> f32 {
    render(scene).data.chunks(4).map(|p| p[3]).sum()
}

fn one(width: u32, height: u32, shape: Shape) -> Scene {
    let mut s = Scene::new(width, height, Rgba::TRANSPARENT).unwrap();
    s.shapes.push(shape);
    s
}

#[test]
fn caps_end_where_svg_ends_them() {
    // A 20 px line, 6 px wide, colour alpha 0.8: butt covers 20 x 6, square 26 x 6, round
    // 20 x 6 plus a disc of radius 3.
    let area = |cap| {
        let st = styled(cap, LineJoin::Miter, 4.0, 6.0);
        alpha_sum(&one(40, 20, polyline(&[(10.0, 10.0), (30.0, 10.0)], st))) / 0.8
    };
    let pi = std::f32::consts::PI;
    for (cap, want) in [
        (LineCap::Butt, 120.0),
        (LineCap::Square, 156.0),
        (LineCap::Round, 120.0 + 9.0 * pi),
    ] {
        let got = area(cap);
        assert!((got - want).abs() < 0.01 * want, "{cap:?}: {got} vs {want}");
    }
    let butt = render(&one(
        40,
        20,
        polyline(
            &[(10.0, 10.0), (30.0, 10.0)],
            styled(LineCap::Butt, LineJoin::Miter, 4.0, 6.0),
        ),
    ));
    assert_eq!(butt.pixel(9, 10)[3], 0.0);
    assert!((butt.pixel(10, 10)[3] - 0.8).abs() < 1e-5);
    assert!((butt.pixel(29, 12)[3] - 0.8).abs() < 1e-5);
    assert_eq!(butt.pixel(30, 10)[3], 0.0);
}

#[test]
fn joins_reach_the_corner_until_the_miter_limit() {
    // A right angle at (25, 25), 6 px wide: the miter's outer corner is (28, 28), √2 widths
    // from the path; the bevel cuts the corner along x + y = 53; a round join reaches 3 px.
    let corner = |join, limit| {
        let st = styled(LineCap::Butt, join, limit, 6.0);
        render(&one(
            34,
            34,
            polyline(&[(5.0, 25.0), (25.0, 25.0), (25.0, 5.0)], st),
        ))
        .pixel(27, 27)[3]
            / 0.8
    };
    assert!(corner(LineJoin::Miter, 4.0) > 0.99);
    assert!(corner(LineJoin::Miter, 1.5) > 0.99);
    assert!(
        corner(LineJoin::Miter, 1.4) < 0.01,
        "past the limit: bevelled"
    );
    assert!(corner(LineJoin::Bevel, 4.0) < 0.01);
    assert!(corner(LineJoin::Round, 4.0) < 0.01);
    // Between bevel and miter: the pixel whose centre (26.5, 26.5) is inside the miter, and
    // inside the bevel too (26.5 + 26.5 = 53 lies on it: half covered).
    let st = styled(LineCap::Butt, LineJoin::Bevel, 4.0, 6.0);
    let bevel = render(&one(
        34,
        34,
        polyline(&[(5.0, 25.0), (25.0, 25.0), (25.0, 5.0)], st),
    ));
    assert!((bevel.pixel(26, 26)[3] / 0.8 - 0.5).abs() < 0.15);
}

#[test]
fn shaped_stroke_gradients_match_finite_differences() {
    let cases = [
        (LineCap::Butt, LineJoin::Miter, 4.0),
        (LineCap::Square, LineJoin::Bevel, 4.0),
        (LineCap::Butt, LineJoin::Miter, 1.2),
        (LineCap::Round, LineJoin::Miter, 10.0),
        (LineCap::Square, LineJoin::Round, 4.0),
    ];
    for (i, (cap, join, limit)) in cases.into_iter().enumerate() {
        let mut s = Scene::new(24, 20, Rgba::new(0.9, 0.9, 0.8, 1.0)).unwrap();
        s.shapes.push(polyline(
            &[(3.2, 4.1), (17.3, 5.2), (6.4, 15.3), (20.6, 16.7)],
            styled(cap, join, limit, 3.1),
        ));
        let curve = Point::list(&[(2.5, 18.0), (8.0, 2.0), (14.0, 26.0), (22.4, 9.3)]);
        s.shapes
            .push(Shape::open_cubic(curve, styled(cap, join, limit, 1.3)).unwrap());
        // Off the pixel grid: a pixel centre exactly on a piece's edge is a tie between pieces
        // whose slopes differ (either is a subgradient; central differences average them).
        let mut square = Shape::square(9.37, 7.61, 6.23, Rgba::new(1.0, 0.2, 0.1, 0.6)).unwrap();
        square.stroke = Some(styled(cap, join, limit, 2.2));
        s.shapes.push(square);
        let (checked, bad) = fd_check(&s, 300 + i as u64);
        assert!(
            bad.len() * 50 <= checked,
            "{cap:?} {join:?} {limit}: {} of {checked} mismatched:\n{}",
            bad.len(),
            bad.join("\n")
        );
    }
}

#[test]
fn zero_length_strokes_draw_their_caps() {
    let dot = |cap| {
        let st = styled(cap, LineJoin::Miter, 4.0, 6.0);
        alpha_sum(&one(20, 20, polyline(&[(10.0, 10.0), (10.0, 10.0)], st))) / 0.8
    };
    assert_eq!(dot(LineCap::Butt), 0.0);
    assert!(
        (dot(LineCap::Square) - 36.0).abs() < 0.01,
        "{}",
        dot(LineCap::Square)
    );
    let disc = 9.0 * std::f32::consts::PI;
    assert!((dot(LineCap::Round) - disc).abs() < 0.02 * disc);
}
