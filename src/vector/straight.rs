//! Near-straight segments made straight, so that the writer draws them as lines (`L`, `H`,
//! `V` or the closing `Z`: two numbers or none instead of six).
//!
//! A cubic whose control points lie on its chord, between its ends, traces that chord and
//! nothing else: it fills and strokes exactly as the line does, however the control points are
//! spaced along it. [`collinear_inside`] is that test with a tolerance; [`straighten`] moves
//! the control points of every segment within [`STRAIGHT_TOLERANCE`] of its chord onto it (at
//! the thirds, the line's own cubic), which moves the outline by at most 3/4 of the tolerance.

use crate::scene::{Point, Scene, ShapeKind};

/// Largest distance in pixels of a control point from its chord for [`straighten`]: the
/// outline moves by at most 0.15 px, under the 0.5/255 mean the export allows.
pub const STRAIGHT_TOLERANCE: f32 = 0.2;

/// Whether the control points `c1`, `c2` of the cubic from `a` to `b` lie within `tol` of the
/// chord's line and project onto the chord itself (within `tol` of its ends): the cubic is then
/// the chord, to `tol`. A chord shorter than `tol` is never straight (the segment may loop).
pub(crate) fn collinear_inside(
    a: [f64; 2],
    c1: [f64; 2],
    c2: [f64; 2],
    b: [f64; 2],
    tol: f64,
) -> bool {
    let d = [b[0] - a[0], b[1] - a[1]];
    let len = d[0].hypot(d[1]);
    // Also false for a NaN length.
    if len.partial_cmp(&tol) != Some(std::cmp::Ordering::Greater) {
        return false;
    }
    let u = [d[0] / len, d[1] / len];
    let on = |c: [f64; 2]| {
        let v = [c[0] - a[0], c[1] - a[1]];
        let along = v[0] * u[0] + v[1] * u[1];
        let across = v[0] * u[1] - v[1] * u[0];
        across.abs() <= tol && along >= -tol && along <= len + tol
    };
    on(c1) && on(c2)
}

fn xy(p: Point) -> [f64; 2] {
    [f64::from(p.x), f64::from(p.y)]
}

/// Makes every segment of the cubic outlines of `scene` whose control points lie within `tol`
/// pixels of its chord ([`collinear_inside`]) exactly straight: control points at 1/3 and 2/3
/// of the chord. Polygons are straight already; a simple outline that straightening would make
/// meet itself ([`super::simple::is_simple`]) is left as it was. Returns how many segments
/// changed.
pub fn straighten(scene: &mut Scene, tol: f32) -> usize {
    let mut changed = 0;
    for sh in &mut scene.shapes {
        if sh.kind == ShapeKind::Polygon {
            continue;
        }
        let before = sh.clone();
        let n = straighten_shape(sh, tol);
        if n > 0 && super::simple::is_simple(&before) && !super::simple::is_simple(sh) {
            *sh = before;
        } else {
            changed += n;
        }
    }
    changed
}

/// [`straighten`] on one outline, without the simplicity check.
fn straighten_shape(sh: &mut crate::scene::Shape, tol: f32) -> usize {
    let mut changed = 0;
    for i in 0..sh.num_segments() {
        let [a, c1, c2, b] = sh.segment(i);
        if !collinear_inside(xy(a), xy(c1), xy(c2), xy(b), f64::from(tol)) {
            continue;
        }
        let [t1, t2] = Point::line_controls(a, b);
        if (c1, c2) != (t1, t2) {
            sh.points[3 * i + 1] = t1;
            sh.points[3 * i + 2] = t2;
            changed += 1;
        }
    }
    changed
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Rgba, Shape};

    #[test]
    fn control_points_on_the_chord_are_a_line_wherever_they_sit() {
        let (a, b) = ([0.0, 0.0], [10.0, 0.0]);
        // Unevenly spaced, even crossed over, but on the chord: a line.
        assert!(collinear_inside(a, [7.0, 0.05], [2.0, -0.05], b, 0.1));
        // Off the line, or past an end (the curve would overshoot): not.
        assert!(!collinear_inside(a, [3.0, 0.5], [6.0, 0.0], b, 0.1));
        assert!(!collinear_inside(a, [3.0, 0.0], [10.5, 0.0], b, 0.1));
        // A chord no longer than the tolerance (a loop closing on itself) is no line.
        assert!(!collinear_inside(
            a,
            [3.0, 3.0],
            [-3.0, 3.0],
            [0.05, 0.0],
            0.1
        ));
    }

    #[test]
    fn straighten_moves_near_straight_controls_only_and_keeps_the_render() {
        let mut s = Scene::new(32, 32, Rgba::WHITE).unwrap();
        // A square whose top edge bows by 0.1 px and whose bottom edge bulges by 6 px.
        let pts = Point::list(&[
            (4.0, 4.0),
            (12.0, 4.1),
            (20.0, 3.9),
            (28.0, 4.0),
            (28.0, 12.0),
            (28.0, 20.0),
            (28.0, 28.0),
            (20.0, 34.0),
            (12.0, 34.0),
            (4.0, 28.0),
            (4.0, 20.0),
            (4.0, 12.0),
        ]);
        s.shapes
            .push(Shape::closed_cubic(pts, Rgba::BLACK).unwrap());
        let before = crate::raster::render(&s);
        // Top edge moved onto its chord; the right and left edges are already at the thirds.
        assert_eq!(straighten(&mut s, STRAIGHT_TOLERANCE), 1);
        let p = &s.shapes[0].points;
        assert_eq!((p[1].y, p[2].y), (4.0, 4.0));
        // The bulge stays a curve.
        assert_eq!((p[7].y, p[8].y), (34.0, 34.0));
        let after = crate::raster::render(&s);
        let (mean, max) = super::super::export::diff(&before, &after);
        assert!(mean < 0.5 / 255.0 && max < 0.1, "{mean} {max}");
        // Idempotent.
        assert_eq!(straighten(&mut s, STRAIGHT_TOLERANCE), 0);
    }
}
