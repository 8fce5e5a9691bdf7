//! LIVE end to end through the real rasteriser: convergence, determinism, auto budget,
//! progress/cancel, vtracer init and input validation. Kept small (64 px) so it runs fast.

use std::sync::Mutex;
use vectorfusion::image::{Image, psnr};
use vectorfusion::progress::{CancelToken, NullSink, Progress, Stage};
use vectorfusion::raster;
use vectorfusion::scene::{Point, Rgba, Scene, Shape};
use vectorfusion::stages::live::{InitMode, LiveConfig, LiveError, PathBudget, vectorize};

/// A flat 64 px "icon": background, a red disc, a blue square and a green triangle.
fn target() -> Image {
    let mut s = Scene::new(64, 64, Rgba::WHITE).unwrap();
    s.shapes
        .push(Shape::circle(24.0, 26.0, 14.0, 4, Rgba::new(0.9, 0.1, 0.1, 1.0)).unwrap());
    s.shapes
        .push(Shape::square(36.0, 36.0, 20.0, Rgba::new(0.1, 0.2, 0.8, 1.0)).unwrap());
    s.shapes.push(
        Shape::polygon(
            vec![
                Point::new(40.0, 6.0),
                Point::new(58.0, 28.0),
                Point::new(40.0, 28.0),
            ],
            Rgba::new(0.1, 0.7, 0.2, 1.0),
        )
        .unwrap(),
    );
    raster::render(&s)
}

fn small_cfg() -> LiveConfig {
    LiveConfig {
        size: 64,
        budget: PathBudget::Schedule {
            stages: vec![2, 2, 2],
        },
        iters_per_stage: 60,
        final_iters: 30,
        snapshot_every: 25,
        ..LiveConfig::default()
    }
}

#[test]
fn converges_on_a_rendered_scene() {
    let t = target();
    let blank = Image::filled(64, 64, [1.0, 1.0, 1.0, 1.0]);
    let start = psnr(&blank, &t);
    let r = vectorize(&t, &small_cfg(), &NullSink, &CancelToken::new()).unwrap();
    assert!(r.paths >= 3 && r.paths <= 6, "paths {}", r.paths);
    assert!(r.psnr > 27.0, "psnr {} (blank {start})", r.psnr);
    // Stage PSNR never collapses as paths are added.
    assert_eq!(r.stages.len(), 3);
    assert!(r.stages[2].psnr > r.stages[0].psnr);
    r.scene.validate().unwrap();
    // The SVG renders (resvg) close to our render.
    let svg = vectorfusion::svg::to_svg(&r.scene, &Default::default());
    let back = vectorfusion::stages::live::tracer::render_svg(&svg, 64, 64).unwrap();
    assert!((psnr(&back, &t) - r.psnr).abs() < 2.0);
}

#[test]
fn same_seed_same_svg() {
    let t = target();
    let cfg = LiveConfig {
        iters_per_stage: 15,
        final_iters: 5,
        seed: 42,
        ..small_cfg()
    };
    let a = vectorize(&t, &cfg, &NullSink, &CancelToken::new()).unwrap();
    let b = vectorize(&t, &cfg, &NullSink, &CancelToken::new()).unwrap();
    let opts = vectorfusion::svg::SvgOptions {
        precision: 6,
        ..Default::default()
    };
    assert_eq!(
        vectorfusion::svg::to_svg(&a.scene, &opts),
        vectorfusion::svg::to_svg(&b.scene, &opts)
    );
    let c = vectorize(
        &t,
        &LiveConfig { seed: 43, ..cfg },
        &NullSink,
        &CancelToken::new(),
    )
    .unwrap();
    assert_ne!(a.scene, c.scene, "the seed jitters initial circles");
}

#[test]
fn auto_budget_stops_early_on_a_simple_image() {
    let t = target();
    let cfg = LiveConfig {
        budget: PathBudget::Auto {
            stage: 2,
            max_paths: 24,
            min_gain_db_per_path: 0.5,
            prune_tolerance: 2e-5,
        },
        ..small_cfg()
    };
    let r = vectorize(&t, &cfg, &NullSink, &CancelToken::new()).unwrap();
    assert!(r.paths < 24, "auto chose {} paths", r.paths);
    assert!(r.stages.len() < 12, "stages {}", r.stages.len());
    assert!(r.psnr > 25.0, "psnr {}", r.psnr);
}

#[test]
fn progress_events_and_cancellation() {
    let t = target();
    let events = Mutex::new(Vec::<Progress>::new());
    let sink = |p: Progress| events.lock().unwrap().push(p);
    let cfg = LiveConfig {
        iters_per_stage: 20,
        final_iters: 10,
        snapshot_every: 20,
        ..small_cfg()
    };
    vectorize(&t, &cfg, &sink, &CancelToken::new()).unwrap();
    let ev = events.into_inner().unwrap();
    assert!(ev.len() >= 7);
    assert!(ev.iter().all(|e| e.stage == Stage::Live));
    assert!(ev.windows(2).all(|w| w[0].step <= w[1].step));
    assert!(ev.iter().filter(|e| e.svg.is_some()).count() >= 3);
    assert!(ev.iter().any(|e| e.loss.is_some()));
    let last = ev.last().unwrap();
    assert_eq!(last.step, last.total);
    assert!(last.svg.as_ref().unwrap().starts_with("<svg"));

    let cancel = CancelToken::new();
    cancel.cancel();
    assert!(matches!(
        vectorize(&t, &cfg, &NullSink, &cancel),
        Err(LiveError::Cancelled)
    ));
}

#[test]
fn vtracer_init_starts_close_and_refines() {
    let t = target();
    let cfg = LiveConfig {
        init: InitMode::Vtracer,
        budget: PathBudget::Schedule { stages: vec![4] },
        iters_per_stage: 40,
        // The last stage re-initialises a weak path (a lobe cut off a looping outline) as a
        // fresh circle: the final pass needs a few dozen steps to fit it.
        final_iters: 40,
        ..small_cfg()
    };
    let r = vectorize(&t, &cfg, &NullSink, &CancelToken::new()).unwrap();
    assert_eq!(r.stages[0].stage, 0, "stage 0 is the vtracer start");
    assert_eq!(
        r.stages[0].added, 3,
        "three shapes; the background is not a path"
    );
    assert!(r.paths <= 4);
    assert!(r.psnr > 27.0, "psnr {}", r.psnr);
}

#[test]
fn bad_inputs_are_errors() {
    let t = target();
    let bad = LiveConfig {
        size: 0,
        ..small_cfg()
    };
    assert!(matches!(
        vectorize(&t, &bad, &NullSink, &CancelToken::new()),
        Err(LiveError::Config(_))
    ));
    let bad = LiveConfig {
        budget: PathBudget::Schedule { stages: vec![4, 0] },
        ..small_cfg()
    };
    assert!(vectorize(&t, &bad, &NullSink, &CancelToken::new()).is_err());
    let mut img = t.clone();
    img.data[5] = f32::NAN;
    assert!(matches!(
        vectorize(&img, &small_cfg(), &NullSink, &CancelToken::new()),
        Err(LiveError::Target(_))
    ));
    let empty = Image {
        width: 0,
        height: 0,
        data: vec![],
    };
    assert!(vectorize(&empty, &small_cfg(), &NullSink, &CancelToken::new()).is_err());
}

/// Keeps every state a run hands over.
struct Keep(Mutex<Vec<vectorfusion::stages::live::LiveState>>);

impl vectorfusion::stages::live::LiveCheckpoint for Keep {
    fn save(
        &self,
        state: &vectorfusion::stages::live::LiveState,
    ) -> Result<(), vectorfusion::progress::CheckpointError> {
        self.0.lock().unwrap().push(state.clone());
        Ok(())
    }
}

#[test]
fn coarse_to_fine_works_small_then_full_and_resumes_exactly() {
    use vectorfusion::stages::live::vectorize_resumable;
    let t = target();
    let cfg = LiveConfig {
        coarse_size: 32,
        ..small_cfg()
    };
    let keep = Keep(Mutex::new(Vec::new()));
    let cancel = CancelToken::new();
    let r = vectorize_resumable(&t, &cfg, &NullSink, &cancel, None, Some(&keep)).unwrap();
    let states = keep.0.into_inner().unwrap();
    // The stages before the last at 32 px, the last at 64 px; the result at the target's size.
    let sides: Vec<u32> = states.iter().map(|s| s.scene.width).collect();
    assert_eq!(sides, vec![32, 32, 64]);
    assert_eq!((r.scene.width, r.scene.height), (64, 64));
    assert!(r.psnr > 25.0, "psnr {}", r.psnr);
    // It differs from a run at 64 px throughout, and costs the same number of steps.
    let plain = vectorize(&t, &small_cfg(), &NullSink, &cancel).unwrap();
    assert_ne!(plain.scene, r.scene);
    assert_eq!(plain.steps, r.steps);
    // Resumed from a coarse state or from the full-size one: the same scene.
    for st in [&states[0], &states[2]] {
        let again =
            vectorize_resumable(&t, &cfg, &NullSink, &cancel, Some(st.clone()), None).unwrap();
        assert_eq!(again.scene, r.scene, "resumed at stage {}", st.next_stage);
    }
}

#[test]
fn coarse_size_out_of_range_is_a_config_error() {
    let cfg = LiveConfig {
        coarse_size: 4,
        ..small_cfg()
    };
    let err = vectorize(&target(), &cfg, &NullSink, &CancelToken::new()).unwrap_err();
    assert!(
        matches!(err, LiveError::Config(ref m) if m.contains("coarse_size")),
        "{err}"
    );
}
