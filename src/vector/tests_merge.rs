//! Tests of [`super`]: what merges, what does not, and that the picture stays.

use super::*;
use crate::scene::Rgba;

const RED: Rgba = Rgba::new(0.8, 0.1, 0.1, 1.0);
const BLUE: Rgba = Rgba::new(0.1, 0.2, 0.9, 1.0);

fn scene(shapes: Vec<Shape>) -> Scene {
    let mut s = Scene::new(96, 96, Rgba::WHITE).unwrap();
    s.shapes = shapes;
    s
}

fn circle(x: f32, y: f32, r: f32, c: Rgba) -> Shape {
    Shape::circle(x, y, r, 4, c).unwrap()
}

#[test]
fn overlapping_same_fill_paths_become_one_simple_path_and_the_picture_stays() {
    let mut s = scene(vec![
        circle(35.0, 48.0, 20.0, RED),
        circle(60.0, 48.0, 20.0, RED),
    ]);
    let before = crate::raster::render(&s);
    assert_eq!(merge_touching(&mut s, MergeTolerance::default()), 1);
    assert_eq!(s.shapes.len(), 1);
    assert!(super::super::simple::is_simple(&s.shapes[0]));
    let (mean, max) = super::super::export::diff(&before, &crate::raster::render(&s));
    assert!(mean < 0.5 / 255.0 && max < 0.3, "{mean} {max}");
    // Deterministic.
    let mut again = scene(vec![
        circle(35.0, 48.0, 20.0, RED),
        circle(60.0, 48.0, 20.0, RED),
    ]);
    merge_touching(&mut again, MergeTolerance::default());
    assert_eq!(again, s);
}

#[test]
fn apart_or_differently_filled_paths_stay() {
    let apart = vec![circle(20.0, 20.0, 10.0, RED), circle(70.0, 70.0, 10.0, RED)];
    let mut s = scene(apart.clone());
    assert_eq!(merge_touching(&mut s, MergeTolerance::default()), 0);
    assert_eq!(s.shapes, apart);
    let colours = vec![
        circle(35.0, 48.0, 20.0, RED),
        circle(60.0, 48.0, 20.0, BLUE),
    ];
    let mut s = scene(colours.clone());
    assert_eq!(merge_touching(&mut s, MergeTolerance::default()), 0);
    assert_eq!(s.shapes, colours);
}

#[test]
fn a_path_of_another_colour_between_them_over_both_blocks_the_merge() {
    // Blue lies over the lower red and under the upper red: no place in the paint order keeps
    // the picture.
    let shapes = vec![
        circle(35.0, 48.0, 20.0, RED),
        circle(48.0, 48.0, 12.0, BLUE),
        circle(60.0, 48.0, 20.0, RED),
    ];
    let mut s = scene(shapes.clone());
    assert_eq!(merge_touching(&mut s, MergeTolerance::default()), 0);
    assert_eq!(s.shapes, shapes);
    // Blue over the lower one only: the union goes in the lower one's place.
    let shapes = vec![
        circle(30.0, 48.0, 20.0, RED),
        circle(20.0, 48.0, 6.0, BLUE),
        circle(55.0, 48.0, 20.0, RED),
    ];
    let mut s = scene(shapes);
    let before = crate::raster::render(&s);
    assert_eq!(merge_touching(&mut s, MergeTolerance::default()), 1);
    assert_eq!(s.shapes.len(), 2);
    assert_eq!(s.shapes[1].fill, Some(BLUE));
    let (mean, _) = super::super::export::diff(&before, &crate::raster::render(&s));
    assert!(mean < 0.5 / 255.0, "{mean}");
}

#[test]
fn a_union_with_a_hole_is_not_one_path() {
    // Two C shapes closing a ring: the union has a hole, which one simple outline cannot hold.
    let p = |x: f32, y: f32| crate::scene::Point::new(x, y);
    let upper = Shape::polygon(
        vec![
            p(10.0, 50.0),
            p(10.0, 10.0),
            p(90.0, 10.0),
            p(90.0, 50.0),
            p(70.0, 50.0),
            p(70.0, 30.0),
            p(30.0, 30.0),
            p(30.0, 50.0),
        ],
        RED,
    )
    .unwrap();
    let lower = Shape::polygon(
        vec![
            p(10.0, 49.0),
            p(30.0, 49.0),
            p(30.0, 70.0),
            p(70.0, 70.0),
            p(70.0, 49.0),
            p(90.0, 49.0),
            p(90.0, 90.0),
            p(10.0, 90.0),
        ],
        RED,
    )
    .unwrap();
    assert!(union_shape(&upper, &lower).is_none());
}

#[test]
fn the_finish_keeps_groups_on_their_shapes() {
    // A looping outline (split into lobes), a hidden circle (dropped) and two touching red
    // circles (merged) inside a half-opaque group, after a blue circle outside it.
    let p = |x: f32, y: f32| crate::scene::Point::new(x, y);
    let eight = Shape::closed_cubic(
        vec![
            p(48.0, 30.0),
            p(60.0, 18.0),
            p(80.0, 18.0),
            p(80.0, 30.0),
            p(80.0, 42.0),
            p(60.0, 42.0),
            p(48.0, 30.0),
            p(36.0, 18.0),
            p(16.0, 18.0),
            p(16.0, 30.0),
            p(16.0, 42.0),
            p(36.0, 42.0),
        ],
        BLUE,
    )
    .unwrap();
    let mut s = scene(vec![
        circle(20.0, 75.0, 12.0, BLUE),
        circle(58.0, 70.0, 4.0, RED),
        eight,
        circle(35.0, 70.0, 14.0, RED),
        circle(58.0, 70.0, 14.0, RED),
    ]);
    s.groups = vec![crate::scene::Group::new(1..5, 0.5)];
    s.validate().unwrap();
    let before = crate::raster::render(&s);
    let report = crate::vector::finish_scene(&mut s, &crate::vector::ColorPlan::default(), true);
    assert!(
        report.split >= 1 && report.dropped >= 1 && report.merged >= 1,
        "{report:?}"
    );
    s.validate().unwrap();
    assert_eq!(s.groups.len(), 1);
    let g = &s.groups[0];
    assert_eq!(
        (g.start, g.end),
        (1, s.shapes.len()),
        "every later shape stays inside"
    );
    assert_eq!(s.shapes[0].points, circle(20.0, 75.0, 12.0, BLUE).points);
    let (mean, _) = super::super::export::diff(&before, &crate::raster::render(&s));
    assert!(mean < 1.0 / 255.0, "{}", mean * 255.0);
}
