//! Unit tests of the samplers and their configuration.

use super::*;
use candle_core::Device;

fn cfg(extra: &str) -> SchedulerConfig {
    serde_json::from_str(&format!(
        r#"{{"beta_schedule": "squaredcos_cap_v2", "prediction_type": "v_prediction",
            "timestep_spacing": "trailing"{extra}}}"#
    ))
    .unwrap()
}

/// `clip_sample` clamps x̂₀ (so a wild model output cannot push x outside the data range at
/// the last step) and leaves in-range predictions alone.
#[test]
fn clip_sample_clamps_the_predicted_x0_only() {
    let x = Tensor::from_vec(vec![0.5f32, -0.2, 0.1, 0.0], (1, 1, 2, 2), &Device::Cpu).unwrap();
    // v = -x0 at t = 999 (ᾱ ≈ 0): outputs of ±5 mean x̂₀ ≈ ∓5, far outside [-1, 1].
    let v = Tensor::from_vec(vec![5f32, -5.0, 0.3, -0.3], (1, 1, 2, 2), &Device::Cpu).unwrap();
    let plain = Sampler::new(&cfg(""), SamplerKind::Ddim, 1).unwrap();
    let clip = Sampler::new(&cfg(r#", "clip_sample": true"#), SamplerKind::Ddim, 1).unwrap();
    assert_eq!(clip.timesteps, vec![999.0]);
    let run = |s: &Sampler| -> Vec<f32> {
        s.step(&v, 0, &x, None)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap()
    };
    let (a, b) = (run(&plain), run(&clip));
    assert!(a[0] < -4.0 && a[1] > 4.0, "{a:?}");
    assert!(b[0] >= -1.0 - 1e-6 && b[1] <= 1.0 + 1e-6, "{b:?}");
    assert!((a[2] - b[2]).abs() < 1e-6 && (a[3] - b[3]).abs() < 1e-6);
}

#[test]
fn thresholding_and_bad_clip_range_are_refused() {
    let e = Sampler::new(&cfg(r#", "thresholding": true"#), SamplerKind::Ddim, 4).unwrap_err();
    assert!(e.to_string().contains("thresholding"), "{e}");
    let e = Sampler::new(
        &cfg(r#", "clip_sample": true, "clip_sample_range": 0.0"#),
        SamplerKind::Ddim,
        4,
    )
    .unwrap_err();
    assert!(e.to_string().contains("clip_sample_range"), "{e}");
}

#[test]
fn the_sampler_is_the_one_the_config_names() {
    let named = |class: &str| SamplerKind::of(&cfg(&format!(r#", "_class_name": "{class}""#)));
    assert_eq!(named("EulerDiscreteScheduler"), SamplerKind::Euler);
    assert_eq!(
        named("EulerAncestralDiscreteScheduler"),
        SamplerKind::EulerAncestral
    );
    assert_eq!(named("LCMScheduler"), SamplerKind::Lcm);
    assert_eq!(named("PNDMScheduler"), SamplerKind::Ddim);
    assert_eq!(named("DDIMScheduler"), SamplerKind::Ddim);
    assert_eq!(SamplerRun::noise_count(SamplerKind::Lcm, 4), 3);
    assert_eq!(SamplerRun::noise_count(SamplerKind::EulerAncestral, 2), 2);
    assert_eq!(SamplerRun::noise_count(SamplerKind::Ddim, 9), 0);
    // LCM draws its steps from the teacher's 50: more than that cannot be spaced
    let e = Sampler::new(&cfg(""), SamplerKind::Lcm, 51).unwrap_err();
    assert!(e.to_string().contains("original_inference_steps"), "{e}");
    let s = Sampler::new(&cfg(""), SamplerKind::Lcm, 1).unwrap();
    assert_eq!(s.timesteps, vec![999.0]);
}
