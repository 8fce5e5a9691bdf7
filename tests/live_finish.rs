//! The vector stage's finish on LIVE runs: clean geometry (no outline crossing itself, nothing
//! hidden), colours from a palette or under a cap, the background as asked, and the stopping
//! rules `target_psnr` and `max_bytes`. Small (64 px) so it runs fast.

use vectorfusion::image::{Image, psnr};
use vectorfusion::progress::{CancelToken, NullSink};
use vectorfusion::raster;
use vectorfusion::scene::{Point, Rgba, Scene, Shape};
use vectorfusion::stages::live::{LiveConfig, LiveResult, PathBudget, vectorize};
use vectorfusion::vector::palette::{Background, Color8, ColorPlan, distinct_fills, parse_palette};
use vectorfusion::vector::simple::is_simple;

/// A flat 64 px "icon": a red disc, a blue square, a green triangle and a yellow ring (a
/// shape LIVE's circles tend to fold around), on transparent.
fn target() -> Image {
    let mut s = Scene::new(64, 64, Rgba::TRANSPARENT).unwrap();
    s.shapes
        .push(Shape::circle(22.0, 24.0, 14.0, 4, Rgba::new(0.9, 0.1, 0.1, 1.0)).unwrap());
    s.shapes
        .push(Shape::square(36.0, 36.0, 20.0, Rgba::new(0.1, 0.2, 0.8, 1.0)).unwrap());
    s.shapes.push(
        Shape::polygon(
            vec![
                Point::new(40.0, 4.0),
                Point::new(60.0, 28.0),
                Point::new(40.0, 28.0),
            ],
            Rgba::new(0.1, 0.7, 0.2, 1.0),
        )
        .unwrap(),
    );
    s.shapes
        .push(Shape::circle(16.0, 50.0, 10.0, 8, Rgba::new(0.95, 0.8, 0.1, 1.0)).unwrap());
    s.shapes
        .push(Shape::circle(16.0, 50.0, 5.0, 8, Rgba::WHITE).unwrap());
    raster::render(&s)
}

fn cfg(colors: ColorPlan) -> LiveConfig {
    LiveConfig {
        size: 64,
        budget: PathBudget::Schedule {
            stages: vec![3, 3, 4],
        },
        iters_per_stage: 60,
        final_iters: 30,
        snapshot_every: 0,
        colors,
        ..LiveConfig::default()
    }
}

fn run(c: &LiveConfig) -> LiveResult {
    vectorize(&target(), c, &NullSink, &CancelToken::new()).unwrap()
}

#[test]
fn every_path_is_simple_and_visible_across_seeds() {
    for seed in 0..4 {
        let r = run(&LiveConfig {
            seed,
            xing_weight: 0.0,
            ..cfg(ColorPlan::default())
        });
        let e = &r.editability;
        assert_eq!(e.paths, r.scene.shapes.len(), "seed {seed}");
        assert_eq!(e.self_intersecting, 0, "seed {seed}: {e:?}");
        assert_eq!(e.hidden, 0, "seed {seed}: {e:?}");
        assert!(r.scene.shapes.iter().all(is_simple), "seed {seed}");
        assert!(r.psnr > 20.0, "seed {seed}: psnr {}", r.psnr);
    }
}

#[test]
fn a_palette_restricts_every_fill() {
    let pal = parse_palette("#e61a1a,#1a33cc,#1ab333,#f2cc1a,#ffffff").unwrap();
    let r = run(&cfg(ColorPlan {
        palette: Some(pal.clone()),
        ..ColorPlan::default()
    }));
    for sh in &r.scene.shapes {
        let f = Color8::from_rgba(sh.fill.unwrap());
        assert!(pal.contains(&f), "{f} is not in the palette");
    }
    assert!(r.psnr > 20.0, "psnr {}", r.psnr);
}

#[test]
fn a_colour_cap_bounds_distinct_fills() {
    for n in [1u32, 2, 3] {
        let r = run(&cfg(ColorPlan {
            colors: Some(n),
            ..ColorPlan::default()
        }));
        assert!(
            distinct_fills(&r.scene) <= n as usize,
            "--colors {n}: {} fills",
            distinct_fills(&r.scene)
        );
    }
    let free = run(&cfg(ColorPlan::default()));
    let capped = run(&cfg(ColorPlan {
        colors: Some(2),
        ..ColorPlan::default()
    }));
    assert!(free.psnr > capped.psnr, "{} vs {}", free.psnr, capped.psnr);
}

#[test]
fn background_is_as_asked() {
    // A transparent border: `auto` writes no background rectangle.
    let auto = run(&cfg(ColorPlan::default()));
    assert_eq!(auto.scene.background.a, 0.0);
    let fixed = run(&cfg(ColorPlan {
        background: Background::Color(Color8([10, 20, 30])),
        ..ColorPlan::default()
    }));
    assert_eq!(
        Color8::from_rgba(fixed.scene.background),
        Color8([10, 20, 30])
    );
    assert_eq!(fixed.scene.background.a, 1.0);
    // An opaque target keeps a background rectangle of its border colour under `auto`.
    let opaque = target().over([0.2, 0.3, 0.4]);
    let r = vectorize(
        &opaque,
        &cfg(ColorPlan::default()),
        &NullSink,
        &CancelToken::new(),
    )
    .unwrap();
    assert_eq!(r.scene.background.a, 1.0);
    let transparent = vectorize(
        &opaque,
        &cfg(ColorPlan {
            background: Background::Transparent,
            ..ColorPlan::default()
        }),
        &NullSink,
        &CancelToken::new(),
    )
    .unwrap();
    assert_eq!(transparent.scene.background.a, 0.0);
}

#[test]
fn target_psnr_and_max_bytes_stop_adding_paths() {
    let auto = |target_psnr, max_bytes| LiveConfig {
        budget: PathBudget::Auto {
            stage: 2,
            max_paths: 24,
            min_gain_db_per_path: 0.0,
            prune_tolerance: 0.0,
        },
        target_psnr,
        max_bytes,
        ..cfg(ColorPlan::default())
    };
    let full = run(&auto(None, None));
    let low = run(&auto(Some(18.0), None));
    assert!(low.paths < full.paths, "{} vs {}", low.paths, full.paths);
    assert!(low.psnr >= 18.0 - 1.0, "psnr {}", low.psnr);
    let small = run(&auto(None, Some(700)));
    // The SVG the run writes (the compact writer's) stays within the budget.
    let svg = vectorfusion::vector::write_svg(&small.scene, &ColorPlan::default());
    assert!(svg.len() <= 700, "{} bytes", svg.len());
    assert!(small.paths >= 1);
}

#[test]
fn the_finish_is_deterministic() {
    let c = cfg(ColorPlan {
        colors: Some(3),
        ..ColorPlan::default()
    });
    assert_eq!(run(&c).scene, run(&c).scene);
}

#[test]
fn psnr_of_the_result_is_measured_on_it() {
    let r = run(&cfg(ColorPlan::default()));
    assert!((psnr(&raster::render(&r.scene), &target()) - r.psnr).abs() < 1e-9);
}

#[test]
fn the_early_stop_takes_fewer_steps_and_still_fits() {
    let full = run(&cfg(ColorPlan::default()));
    let early = run(&LiveConfig {
        converge_tol: 0.5,
        ..cfg(ColorPlan::default())
    });
    // Progress still counts every planned step; the loss history is what shrinks. The early
    // run ends elsewhere and no worse than a few dB.
    assert_eq!(early.steps, full.steps);
    assert_ne!(early.scene, full.scene);
    assert!(
        early.psnr > full.psnr - 4.0,
        "{} vs {}",
        early.psnr,
        full.psnr
    );
    assert_eq!(early.editability.self_intersecting, 0);
}

#[test]
fn paths_carry_their_stage_and_the_svg_groups_by_it() {
    let c = cfg(ColorPlan {
        group: vectorfusion::vector::palette::Grouping::Stage,
        ..ColorPlan::default()
    });
    let r = run(&c);
    // Every path was added by one of the three stages (splits and merges keep the tag).
    assert!(
        r.scene
            .shapes
            .iter()
            .all(|s| s.stage.is_some_and(|k| (1..=3).contains(&k))),
        "{:?}",
        r.scene.shapes.iter().map(|s| s.stage).collect::<Vec<_>>()
    );
    let svg = vectorfusion::vector::write_svg(&r.scene, &c.colors);
    let first = r.scene.shapes[0].stage.unwrap();
    assert!(svg.contains(&format!(r#"<g id="s{first}">"#)), "{svg}");
    assert_eq!(svg.matches("<path").count(), r.paths, "{svg}");
    // The grouping changes the text, not the picture.
    let plain = vectorfusion::vector::write_svg(&r.scene, &ColorPlan::default());
    let render = |t: &str| raster::render(&vectorfusion::svg::from_svg(t).unwrap());
    assert_eq!(render(&svg).data, render(&plain).data);
}

#[test]
fn touching_paths_of_one_fill_are_merged_once_and_for_all() {
    let r = run(&cfg(ColorPlan {
        colors: Some(3),
        ..ColorPlan::default()
    }));
    // What the finish left has no pair that still merges.
    let mut again = r.scene.clone();
    let more = vectorfusion::vector::merge::merge_touching(&mut again, Default::default());
    assert_eq!(more, 0);
    assert!(r.scene.shapes.iter().all(is_simple));
}

/// A 96 px target (traced at 64 px, so the working scene is scaled by 1.5 on the way out)
/// whose shapes run off every edge: a disc over the top-left corner, a band across the
/// right edge, a bar along the bottom.
fn off_the_edges() -> Image {
    let mut s = Scene::new(96, 96, Rgba::WHITE).unwrap();
    s.shapes
        .push(Shape::circle(4.0, 6.0, 30.0, 8, Rgba::new(0.9, 0.1, 0.1, 1.0)).unwrap());
    s.shapes
        .push(Shape::square(90.0, 48.0, 28.0, Rgba::new(0.1, 0.2, 0.8, 1.0)).unwrap());
    s.shapes.push(
        Shape::polygon(
            vec![
                Point::new(20.0, 86.0),
                Point::new(76.0, 86.0),
                Point::new(76.0, 100.0),
                Point::new(20.0, 100.0),
            ],
            Rgba::new(0.1, 0.7, 0.2, 1.0),
        )
        .unwrap(),
    );
    raster::render(&s)
}

#[test]
fn outlines_are_cut_to_the_canvas_they_are_written_on() {
    let target = off_the_edges();
    let mut cut = 0;
    for seed in 0..3 {
        let c = LiveConfig {
            seed,
            ..cfg(ColorPlan::default())
        };
        let r = vectorize(&target, &c, &NullSink, &CancelToken::new()).unwrap();
        assert_eq!((r.scene.width, r.scene.height), (96, 96));
        cut += r.cut;
        // Every outline (its curve, not its handles) lies on the canvas, and stays simple.
        for (i, s) in r.scene.shapes.iter().enumerate() {
            for (x, y) in vectorfusion::vector::simple::flatten(s, 0.05) {
                assert!(
                    (-1e-3..=96.001).contains(&x) && (-1e-3..=96.001).contains(&y),
                    "seed {seed}, path {i}: ({x}, {y})"
                );
            }
            assert!(is_simple(s), "seed {seed}, path {i}");
        }
        // The trace still fits its target (cutting changes no pixel on the canvas).
        assert!(r.psnr > 24.0, "seed {seed}: {}", r.psnr);
        // Cut pieces end on the canvas's edges, not short of them: the corner pixel is red.
        let img = raster::render(&r.scene);
        let px = &img.data[..3];
        assert!(px[0] > 0.7 && px[1] < 0.35, "seed {seed}: corner {px:?}");
    }
    assert!(cut > 0, "no path reached past the canvas in three seeds");
}
