//! Unit tests of [`super`] (palettes, colour choice, merging).

use super::*;
use crate::scene::Shape;

fn square(x: f32, y: f32, s: f32, c: Rgba) -> Shape {
    Shape::square(x, y, s, c).unwrap()
}

#[test]
fn hex_colours_parse_and_print() {
    assert_eq!("#fff".parse::<Color8>().unwrap(), Color8([255, 255, 255]));
    assert_eq!(
        " #E63946 ".parse::<Color8>().unwrap(),
        Color8([0xe6, 0x39, 0x46])
    );
    assert_eq!(Color8([1, 2, 255]).to_string(), "#0102ff");
    for bad in ["fff", "#ffff", "#gggggg", "#12345", "", "#", "#ff ff ff"] {
        assert!(bad.parse::<Color8>().is_err(), "{bad:?}");
    }
}

#[test]
fn palettes_and_backgrounds_validate() {
    assert_eq!(parse_palette("#000,#fff,#000").unwrap().len(), 2);
    assert_eq!(parse_palette(""), Err(ColorError::EmptyPalette));
    assert!(matches!(parse_palette("#000,red"), Err(ColorError::Hex(_))));
    let many: Vec<String> = (0..65).map(|i| format!("#0000{i:02x}")).collect();
    assert_eq!(parse_palette(&many.join(",")), Err(ColorError::TooMany(65)));
    assert_eq!(check_colors(0), Err(ColorError::Count(0)));
    assert_eq!(check_colors(65), Err(ColorError::Count(65)));
    assert_eq!(
        "transparent".parse::<Background>().unwrap(),
        Background::Transparent
    );
    assert_eq!(
        "#102030".parse::<Background>().unwrap(),
        Background::Color(Color8([16, 32, 48]))
    );
    assert!("blue".parse::<Background>().is_err());
    let plan = ColorPlan {
        colors: None,
        palette: Some(vec![Color8([1, 2, 3])]),
        background: Background::Color(Color8([9, 9, 9])),
        group: Grouping::Color,
    };
    let json = serde_json::to_string(&plan).unwrap();
    assert!(json.contains("\"#010203\"") && json.contains("\"background\":\"#090909\""));
    assert_eq!(serde_json::from_str::<ColorPlan>(&json).unwrap(), plan);
    assert_eq!(
        ColorPlan {
            colors: Some(0),
            ..ColorPlan::default()
        }
        .validate()
        .unwrap_err()
        .0,
        "colors"
    );
    // Both: at most `colors` of the user's entries, those nearest the colours found.
    let both = ColorPlan {
        colors: Some(2),
        palette: Some(parse_palette("#000,#f00,#0f0,#00f").unwrap()),
        ..ColorPlan::default()
    };
    both.validate().unwrap();
    let found = |k: usize| {
        assert_eq!(k, 2);
        vec![Rgba::new(0.9, 0.1, 0.0, 1.0), Rgba::new(0.1, 0.0, 0.8, 1.0)]
    };
    assert_eq!(
        both.resolve(found).unwrap(),
        vec![Rgba::new(1.0, 0.0, 0.0, 1.0), Rgba::new(0.0, 0.0, 1.0, 1.0)]
    );
    assert_eq!(ColorPlan::default().resolve(|_| unreachable!()), None);
}

#[test]
fn visibility_counts_only_what_shows() {
    let red = Rgba::new(1.0, 0.0, 0.0, 1.0);
    let blue = Rgba::new(0.0, 0.0, 1.0, 1.0);
    let mut scene = Scene::new(32, 32, Rgba::WHITE).unwrap();
    scene.shapes.push(square(4.0, 4.0, 8.0, red)); // fully under the blue one
    scene.shapes.push(square(2.0, 2.0, 16.0, blue));
    scene.shapes.push(square(20.0, 20.0, 4.0, red));
    let v = visibility(&scene, None);
    assert!(v[0].area < 1e-3, "{:?}", v[0]);
    assert!((v[1].area - 256.0).abs() < 1e-2, "{:?}", v[1]);
    assert!((v[2].area - 16.0).abs() < 1e-2, "{:?}", v[2]);
}

#[test]
fn choice_minimises_loss_among_the_palette() {
    // Target: a dark-orange square; the path covers it. Palette: red, orange, white.
    let mut target_scene = Scene::new(16, 16, Rgba::WHITE).unwrap();
    let orange = Rgba::new(0.9, 0.5, 0.1, 1.0);
    target_scene.shapes.push(square(4.0, 4.0, 8.0, orange));
    let target = crate::raster::render(&target_scene);
    let mut scene = Scene::new(16, 16, Rgba::WHITE).unwrap();
    scene
        .shapes
        .push(square(4.0, 4.0, 8.0, Rgba::new(0.2, 0.2, 0.2, 1.0)));
    let palette = [
        Rgba::new(1.0, 0.0, 0.0, 1.0),
        Rgba::new(1.0, 0.6, 0.0, 1.0),
        Rgba::WHITE,
    ];
    assert_eq!(choose_fills(&mut scene, Some(&target), &palette), 1);
    let chosen = scene.shapes[0].fill.unwrap();
    // Brute force: the loss of every palette entry; the chosen one is the smallest.
    let loss = |c: Rgba| {
        let mut s = scene.clone();
        s.shapes[0].fill = Some(c);
        crate::image::mse_rgb_over_white(&crate::raster::render(&s), &target)
    };
    for p in palette {
        assert!(loss(chosen) <= loss(p) + 1e-9);
    }
    assert_eq!(chosen, palette[1]);
}

#[test]
fn kmeans_finds_separated_clusters_deterministically() {
    let mut pts = Vec::new();
    let mut w = Vec::new();
    for i in 0..30 {
        let e = i as f32 * 0.001;
        pts.push([0.1 + e, 0.1, 0.1]);
        pts.push([0.9, 0.9 - e, 0.1]);
        pts.push([0.1, 0.2, 0.9 - e]);
        w.extend([1.0, 2.0, 3.0]);
    }
    let a = kmeans(&pts, &w, 3, 20);
    assert_eq!(a, kmeans(&pts, &w, 3, 20));
    assert_eq!(a.len(), 3);
    for want in [[0.1, 0.1, 0.1], [0.9, 0.9, 0.1], [0.1, 0.2, 0.9]] {
        assert!(a.iter().any(|c| dist2(*c, want) < 0.01), "{a:?}");
    }
    assert_eq!(kmeans(&pts[..1], &w[..1], 4, 20).len(), 1);
}

#[test]
fn image_palette_has_at_most_k_colours() {
    let mut s = Scene::new(32, 32, Rgba::WHITE).unwrap();
    s.shapes
        .push(square(2.0, 2.0, 10.0, Rgba::new(1.0, 0.0, 0.0, 1.0)));
    s.shapes
        .push(square(16.0, 16.0, 10.0, Rgba::new(0.0, 0.5, 0.0, 1.0)));
    let img = crate::raster::render(&s);
    let p = palette_of_image(&img, 3);
    assert_eq!(p.len(), 3);
    for want in [[1.0, 0.0, 0.0], [0.0, 0.5, 0.0], [1.0, 1.0, 1.0]] {
        assert!(p.iter().any(|c| dist2(fill_rgb(Some(*c)), want) < 0.005));
    }
}

#[test]
fn merge_joins_near_equal_fills_only() {
    let mut s = Scene::new(32, 32, Rgba::WHITE).unwrap();
    s.shapes
        .push(square(0.0, 0.0, 8.0, Rgba::new(0.50, 0.20, 0.20, 1.0)));
    s.shapes
        .push(square(10.0, 0.0, 8.0, Rgba::new(0.51, 0.21, 0.20, 0.99)));
    s.shapes
        .push(square(20.0, 0.0, 8.0, Rgba::new(0.2, 0.2, 0.8, 1.0)));
    assert_eq!(distinct_fills(&s), 3);
    assert_eq!(merge_similar(&mut s, MERGE_DISTANCE), 2);
    assert_eq!(s.shapes[0].fill, s.shapes[1].fill);
    assert_eq!(s.shapes[1].fill.unwrap().a, 1.0);
    assert_ne!(s.shapes[0].fill, s.shapes[2].fill);
}

/// Eight squares in shades a few levels apart of red and of blue, and one small green one.
fn shaded() -> Scene {
    let mut s = Scene::new(64, 64, Rgba::WHITE).unwrap();
    for i in 0..4 {
        let d = 0.02 * i as f32;
        let (x, y) = (2.0 + 15.0 * i as f32, 2.0);
        s.shapes
            .push(square(x, y, 12.0, Rgba::new(0.8 + d, 0.1, 0.1 + d, 1.0)));
        s.shapes.push(square(
            x,
            y + 20.0,
            12.0,
            Rgba::new(0.1, 0.2 - d, 0.7 + d, 1.0),
        ));
    }
    s.shapes
        .push(square(30.0, 48.0, 6.0, Rgba::new(0.1, 0.7, 0.2, 1.0)));
    s
}

#[test]
fn the_fewest_colours_keep_the_picture() {
    let s = shaded();
    assert_eq!(distinct_fills(&s), 9);
    let reference = crate::raster::render(&s);
    let p = fewest_colours(&s, FEWEST_COLOURS_PSNR).expect("a smaller palette");
    // The shades fold into a few colours; the small green square keeps its own.
    assert!((3..=5).contains(&p.len()), "{p:?}");
    assert!(p.iter().any(|c| c.g > 0.6 && c.r < 0.3), "{p:?}");
    let mut t = s.clone();
    choose_fills(&mut t, None, &p);
    assert_eq!(distinct_fills(&t), p.len());
    let q = crate::image::psnr(&crate::raster::render(&t), &reference);
    assert!(q >= FEWEST_COLOURS_PSNR, "{q}");
    // One colour fewer would not keep it.
    let mut fewer = s.clone();
    choose_fills(&mut fewer, None, &palette_of_fills(&s, p.len() - 1));
    let q = crate::image::psnr(&crate::raster::render(&fewer), &reference);
    assert!(q < FEWEST_COLOURS_PSNR, "{q}");
    // Asking for a closer render keeps more colours; asking for the picture exactly, all.
    assert!(fewest_colours(&s, 60.0).is_none_or(|q| q.len() > p.len()));
    assert_eq!(fewest_colours(&s, f64::INFINITY), None);
    // A gradient paint anywhere: the flat fills are stand-ins, the colours stay.
    let mut g = s.clone();
    g.shapes[0].gradients = Some(Box::default());
    assert_eq!(fewest_colours(&g, FEWEST_COLOURS_PSNR), None);
}

#[test]
fn distinct_colours_stay_distinct() {
    let mut s = Scene::new(32, 32, Rgba::WHITE).unwrap();
    s.shapes
        .push(square(2.0, 2.0, 12.0, Rgba::new(0.9, 0.1, 0.1, 1.0)));
    s.shapes
        .push(square(18.0, 2.0, 12.0, Rgba::new(0.1, 0.1, 0.9, 1.0)));
    s.shapes
        .push(square(2.0, 18.0, 12.0, Rgba::new(0.1, 0.8, 0.1, 1.0)));
    assert_eq!(fewest_colours(&s, FEWEST_COLOURS_PSNR), None);
    s.shapes.truncate(1);
    assert_eq!(fewest_colours(&s, FEWEST_COLOURS_PSNR), None);
}
