use super::*;
use crate::optim::{AdamConfig, LrSchedule};
use crate::scene::{Rgba, Shape};
use crate::stages::styles::Style;

#[test]
fn saturation_penalty_gradient_matches_finite_differences() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut im = Image::new(5, 4);
    for px in im.data.chunks_exact_mut(4) {
        let a: f32 = rng.random_range(0.2..1.0);
        for c in 0..3 {
            px[c] = a * rng.random::<f32>();
        }
        px[3] = a;
    }
    let mut g = vec![0.0; im.data.len()];
    let v = saturation_penalty(&im, 0.05, &mut g);
    assert!(v > 0.0);
    for i in 0..im.data.len() {
        let h = 1e-3;
        let (mut p, mut m) = (im.clone(), im.clone());
        p.data[i] += h;
        m.data[i] -= h;
        let mut scratch = vec![0.0; im.data.len()];
        let fd = (saturation_penalty(&p, 0.05, &mut scratch)
            - saturation_penalty(&m, 0.05, &mut scratch))
            / (2.0 * h as f64);
        assert!((fd - g[i] as f64).abs() < 1e-5, "i={i} fd={fd} an={}", g[i]);
    }
    // Black (saturated) costs 0.05, mid-grey costs 0.
    let mut z = vec![0.0; 4];
    let black = Image::filled(1, 1, [0.0, 0.0, 0.0, 1.0]);
    assert!((saturation_penalty(&black, 0.05, &mut z) - 0.05).abs() < 1e-6);
    let grey = Image::filled(1, 1, [0.5, 0.5, 0.5, 1.0]);
    assert!(saturation_penalty(&grey, 0.05, &mut z).abs() < 1e-9);
}

#[test]
fn faint_and_tiny_paths_are_reinitialised_with_fresh_moments() {
    let mut scene = Scene::new(64, 64, Rgba::WHITE).unwrap();
    let c = |a| Shape::circle(20.0, 20.0, 8.0, 4, Rgba::new(0.5, 0.5, 0.5, a)).unwrap();
    scene.shapes.push(c(0.9));
    scene.shapes.push(c(0.01));
    scene
        .shapes
        .push(Shape::circle(5.0, 5.0, 1.0, 4, Rgba::BLACK).unwrap());
    let mut params = Params::from_scene(&scene);
    let sched = Style::Iconography.schedules(100);
    let mut adam = Adam::new(
        &params,
        AdamConfig::default(),
        sched,
        Style::Iconography.trainable(),
    );
    let mut g = params.clone();
    g.get_mut(ParamGroup::Points).fill(1.0);
    g.get_mut(ParamGroup::Fill).fill(1.0);
    adam.step(&mut params.clone(), &g);
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let cfg = ReinitConfig::default();
    let before = scene.clone();
    let n = reinit_faint(&mut scene, &mut params, &mut adam, &cfg, &mut rng).unwrap();
    assert_eq!(n, 1);
    assert_eq!(scene.shapes[0], before.shapes[0]);
    assert_ne!(scene.shapes[1], before.shapes[1]);
    assert!(scene.shapes[1].fill.unwrap().a >= 0.7);
    assert_eq!(params, Params::from_scene(&scene));
    let cfg = ReinitConfig {
        min_area: Some(16.0),
        ..cfg
    };
    let n = reinit_faint(&mut scene, &mut params, &mut adam, &cfg, &mut rng).unwrap();
    assert_eq!(n, 1, "the r=1 circle has area < 16 px²");
    assert_eq!(params, Params::from_scene(&scene));
}

#[test]
fn clipping_bounds_each_group_norm() {
    let mut scene = Scene::new(8, 8, Rgba::WHITE).unwrap();
    scene
        .shapes
        .push(Shape::circle(4.0, 4.0, 2.0, 4, Rgba::BLACK).unwrap());
    let mut g = Params::from_scene(&scene);
    assert!(clip_groups(&mut g, 1.0));
    for grp in ParamGroup::ALL {
        let n: f32 = g.get(grp).iter().map(|x| x * x).sum::<f32>().sqrt();
        assert!(n <= 1.0 + 1e-5);
    }
    let mut small = Params::zeros_like(&scene);
    assert!(!clip_groups(&mut small, 1.0));
}

#[test]
fn config_validation_and_style_defaults() {
    let cfg = SdsConfig::for_style(Style::PixelArt, "a cat", 1000, 512);
    assert_eq!(cfg.prompt, "a cat. pixel art. trending on artstation");
    assert_eq!(cfg.saturation_penalty, 0.05);
    assert!(cfg.reinit.is_none());
    assert_eq!(cfg.render_size(512), 600);
    assert!(cfg.validate(1000).is_ok());
    let mut bad = cfg.clone();
    bad.t_max_end = Some(10);
    assert!(bad.validate(1000).is_err());
    bad.t_max_end = None;
    bad.grad_clip = Some(0.0);
    assert!(bad.validate(1000).is_err());
    let icon = SdsConfig::for_style(Style::Iconography, "a cat", 1000, 512);
    assert_eq!(icon.reinit, Some(ReinitConfig::default()));
    assert_eq!(
        icon.schedules.points,
        LrSchedule::WarmupCosine {
            start: 0.02,
            peak: 0.2,
            warmup: 500,
            end: 0.05,
            total: 1000
        }
    );
    assert!((Weighting::OneMinusAlpha.weight(0.25) - 0.75).abs() < 1e-7);
}

#[test]
fn gaussian_has_unit_moments() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let xs: Vec<f64> = (0..20000).map(|_| gaussian(&mut rng) as f64).collect();
    let m = xs.iter().sum::<f64>() / xs.len() as f64;
    let v = xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / xs.len() as f64;
    assert!(m.abs() < 0.03 && (v - 1.0).abs() < 0.05, "{m} {v}");
}
