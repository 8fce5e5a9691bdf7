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
