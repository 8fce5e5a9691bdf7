use super::*;
use crate::models::stable_diffusion::ModelHints;
use crate::pipeline::canvas::SampleShape;
use crate::scene::MAX_PATHS;
use crate::stages::sds::SdsConfig;

fn facts(small_prior: bool) -> ModelFacts {
    ModelFacts {
        name: "m".into(),
        hints: ModelHints {
            small_prior,
            ..ModelHints::default()
        },
        encoder_choice: EncoderChoice::Auto,
        taesd_found: false,
        sample_shape: if small_prior {
            SampleShape::Square
        } else {
            SampleShape::Multiple(64)
        },
        negative_prompt: true,
        size_conditioning: false,
        few_step: false,
    }
}

fn text(req: PlanRequest, small: bool) -> TextPlan {
    resolve(&req, Some(&facts(small)), &Limits::default())
        .unwrap()
        .text
        .unwrap()
}

#[test]
fn omitted_numbers_are_the_presets_and_explicit_ones_win() {
    for small in [false, true] {
        for preset in Preset::ALL {
            let ps = preset.settings_for(small);
            let t = text(
                PlanRequest {
                    preset: *preset,
                    ..PlanRequest::text("a crown")
                },
                small,
            );
            assert_eq!(t.size, ps.size);
            assert_eq!(t.paths as usize, ps.paths);
            assert_eq!(t.sds.as_ref().unwrap().steps, ps.steps);
            let s = t.sample.as_ref().unwrap();
            assert_eq!((s.samples, s.steps as usize), (ps.samples, ps.sample_steps));
            assert_eq!(
                (t.trace.size, t.trace.iters),
                (ps.trace_size, ps.live_iters)
            );
            assert_eq!(t.snapshot_every, ps.snapshot_every);
            assert_eq!(t.model.small_prior, small);
        }
    }
    let t = text(
        PlanRequest {
            paths: Some(5),
            steps: Some(7),
            samples: Some(3),
            seed: 9,
            ..PlanRequest::text("a crown")
        },
        false,
    );
    assert_eq!((t.paths, t.sds.unwrap().steps), (5, 7));
    assert_eq!(t.sample.unwrap().samples, 3);
    assert_eq!(t.seeds, Seeds::from_seed(9));
    // Per style: pixel art is its grid, sketch at most 16 strokes.
    for (style, paths) in [(Style::PixelArt, 1024), (Style::Sketch, 16)] {
        let p = text(
            PlanRequest {
                style,
                ..PlanRequest::text("a crown")
            },
            false,
        );
        assert_eq!(p.paths, paths, "{style:?}");
    }
}

#[test]
fn methods_decide_the_stages() {
    let plan = |method, start| {
        text(
            PlanRequest {
                method,
                start,
                ..PlanRequest::text("x")
            },
            false,
        )
    };
    let scratch = plan(Method::Scratch, StartKind::Method);
    assert!(scratch.sample.is_none());
    let s = scratch.sds.unwrap();
    assert!(s.augment && s.reinit_min_area.is_none());
    let live = plan(Method::SdLive, StartKind::Method);
    assert!(live.sample.is_some() && live.sds.is_none());
    let full = plan(Method::SdLiveSds, StartKind::Method);
    let s = full.sds.unwrap();
    assert!(!s.augment);
    assert_eq!(s.reinit_min_area, Some(min_area_at(full.size)));
    // A given SVG or image is always distilled, never sampled, and traced at the run's size.
    for start in [StartKind::Svg, StartKind::Image] {
        let p = plan(Method::SdLive, start);
        assert!(p.sample.is_none() && p.sds.is_some());
        assert_eq!(p.trace.size, p.size);
    }
}

#[test]
fn limits_are_checked_and_name_the_field() {
    let small = Limits {
        max_paths: 10,
        max_steps: 20,
        max_samples: 2,
        ..Limits::default()
    };
    for (req, field) in [
        (
            PlanRequest {
                paths: Some(11),
                ..PlanRequest::text("x")
            },
            "paths",
        ),
        (
            PlanRequest {
                paths: Some(1),
                steps: Some(21),
                ..PlanRequest::text("x")
            },
            "steps",
        ),
        (
            PlanRequest {
                paths: Some(1),
                steps: Some(1),
                samples: Some(0),
                ..PlanRequest::text("x")
            },
            "samples",
        ),
        (PlanRequest::text("x"), "paths"), // the balanced preset's 64 paths
    ] {
        let e = resolve(&req, Some(&facts(false)), &small).unwrap_err();
        assert_eq!(e.field, field, "{e}");
    }
    let e = resolve(
        &PlanRequest {
            tuning: Tuning {
                t_min: Some(900),
                t_max: Some(100),
                ..Tuning::default()
            },
            ..PlanRequest::text("x")
        },
        Some(&facts(false)),
        &Limits::default(),
    )
    .unwrap_err();
    assert_eq!(e.field, "t_min");
    // No model: text is refused, a vectorize job with a caption is only traced.
    assert!(resolve(&PlanRequest::text("x"), None, &Limits::default()).is_err());
    let v = PlanRequest {
        kind: JobKind::Vectorize,
        ..PlanRequest::text("x")
    };
    let p = resolve(&v, None, &Limits::default()).unwrap();
    assert!(p.text.is_none() && p.vectorize.is_some());
    let p = resolve(&v, Some(&facts(false)), &Limits::default()).unwrap();
    let t = p.text.unwrap();
    assert_eq!(t.start, StartKind::Image);
    assert_eq!(t.paths as usize, Preset::Balanced.vectorize_paths());
    assert!(Preset::Balanced.vectorize_paths() <= MAX_PATHS);
}

#[test]
fn vectorize_plans_follow_the_preset_and_budget() {
    let req = |preset, paths| PlanRequest {
        kind: JobKind::Vectorize,
        caption: None,
        preset,
        paths,
        seed: 4,
        ..PlanRequest::text("")
    };
    let d = resolve(&req(Preset::Draft, Some(6)), None, &Limits::default())
        .unwrap()
        .vectorize
        .unwrap();
    assert_eq!(
        (d.size, d.iters_per_stage, d.final_iters, d.seed),
        (64, 20, 10, 4)
    );
    assert!(matches!(
        d.budget,
        PathBudget::Auto {
            max_paths: 6,
            stage: 6,
            ..
        }
    ));
    let p = resolve(&req(Preset::Paper, None), None, &Limits::default())
        .unwrap()
        .vectorize
        .unwrap();
    let paper = Preset::Paper.live_config();
    assert_eq!((p.size, p.udf_tau), (paper.size, paper.udf_tau));
}

#[test]
fn live_presets_are_valid_and_ordered_by_effort() {
    let [d, f, b, p] =
        [Preset::Draft, Preset::Fast, Preset::Balanced, Preset::Paper].map(Preset::live_config);
    for c in [&d, &f, &b, &p] {
        c.validate().unwrap();
        assert_eq!(c.budget, PathBudget::fixed(64));
        assert_eq!(c.reinit_min_opacity, MIN_OPACITY);
    }
    assert_eq!(f, LiveConfig::default());
    assert!(d.size < f.size && f.size < b.size && b.size < p.size);
    assert!(d.iters_per_stage < f.iters_per_stage);
    assert!(f.iters_per_stage <= b.iters_per_stage && b.iters_per_stage < p.iters_per_stage);
    // Balanced: coarse-to-fine (the stages before the last at half its size); the others not.
    assert_eq!(2 * b.coarse_size, b.size);
    assert!([d.coarse_size, f.coarse_size, p.coarse_size] == [0; 3]);
    assert_eq!(p.reinit_min_area, 64.0);
    // One vocabulary: the older names still parse.
    assert_eq!("quality".parse::<Preset>(), Ok(Preset::Paper));
    assert_eq!("default".parse::<Preset>(), Ok(Preset::Balanced));
}

#[test]
fn stage_configs_come_from_the_plan_alone() {
    for (method, start, small) in [
        (Method::SdLiveSds, StartKind::Method, false),
        (Method::Scratch, StartKind::Method, true),
        (Method::SdLive, StartKind::Image, false),
    ] {
        let t = text(
            PlanRequest {
                method,
                start,
                seed: 11,
                tuning: Tuning {
                    lr_scale: Some(2.0),
                    grad_clip: Some(0.5),
                    ..Tuning::default()
                },
                ..PlanRequest::text("a crown")
            },
            small,
        );
        let live = t.trace_config();
        assert_eq!(
            live,
            LiveConfig {
                size: t.trace.size,
                budget: PathBudget::fixed(t.paths as usize),
                iters_per_stage: t.trace.iters,
                final_iters: t.trace.iters,
                seed: t.seeds.trace,
                snapshot_every: t.snapshot_every,
                colors: t.colors.clone(),
                ..LiveConfig::default()
            }
        );
        let sp = t.sds.clone().unwrap();
        let sds = t.sds_config().unwrap();
        let mut want = SdsConfig::for_style(t.style, "a crown", sp.steps, t.size);
        want.prompt = t.prompt.clone();
        want.guidance = sp.guidance;
        want.seed = t.seeds.sds;
        want.snapshot_every = t.snapshot_every;
        want.t_min = sp.t_min;
        want.t_max = sp.t_max;
        want.t_max_end = sp.t_max_end;
        want.grad_clip = sp.grad_clip;
        want.schedules = want.schedules.scaled(sp.lr_scale);
        if !sp.augment {
            want.augment = None;
        }
        if let Some(r) = want.reinit.as_mut() {
            r.min_area = sp.reinit_min_area;
        }
        assert_eq!(sds, want, "{method:?} {start:?}");
        assert_eq!((sds.t_min, sds.t_max), (T_MIN, T_MAX));
    }
    let sd_live = text(
        PlanRequest {
            method: Method::SdLive,
            ..PlanRequest::text("a crown")
        },
        false,
    );
    assert!(sd_live.sds_config().is_none());
}

#[test]
fn stored_specs_keep_the_request_and_older_ones_still_read() {
    use crate::pipeline::{JobSpec, request_of};
    // A spec stored before the request and the plan were apart: the resolved numbers beside
    // the plan. They read as explicit numbers equal to the plan's, so the job runs its plan.
    let plan = resolve(
        &PlanRequest {
            kind: JobKind::Vectorize,
            caption: None,
            ..PlanRequest::text("")
        },
        None,
        &Limits::default(),
    )
    .unwrap();
    let old = serde_json::json!({
        "kind": "vectorize", "caption": null, "image": "AQID", "svg": null,
        "style": "iconography", "method": "sd_live_sds", "paths": 64, "steps": 500,
        "seed": 0, "samples": 8, "preset": "balanced", "priority": 0, "plan": plan,
    });
    let spec: JobSpec = serde_json::from_value(old).unwrap();
    assert_eq!(
        (spec.paths, spec.steps, spec.samples),
        (Some(64), Some(500), Some(8))
    );
    assert_eq!(spec.plan.as_ref(), Some(&plan));
    assert_eq!(plan.paths(), Some(64));
    // A new spec stores what the request gave: omitted numbers stay omitted.
    let new = JobSpec {
        paths: None,
        steps: None,
        samples: None,
        ..spec.clone()
    };
    let json = serde_json::to_value(&new).unwrap();
    for field in ["paths", "steps", "samples"] {
        assert!(json.get(field).is_none(), "{json}");
    }
    let back: JobSpec = serde_json::from_value(json).unwrap();
    assert_eq!(back, new);
    // The request resolves to the stored plan again.
    assert_eq!(
        resolve(&request_of(&new), None, &Limits::default()).unwrap(),
        plan
    );
}

#[test]
fn encoder_and_prompt_follow_the_model() {
    let mut f = facts(false);
    f.taesd_found = true;
    let t = resolve(&PlanRequest::text("a cat"), Some(&f), &Limits::default())
        .unwrap()
        .text
        .unwrap();
    assert_eq!(
        t.model.encoder,
        EncoderChoice::Taesd,
        "balanced prefers TAESD"
    );
    assert!(t.prompt.starts_with("a cat. minimal flat 2d vector icon"));
    let paper = PlanRequest {
        preset: Preset::Paper,
        ..PlanRequest::text("a cat")
    };
    let t = resolve(&paper, Some(&f), &Limits::default())
        .unwrap()
        .text
        .unwrap();
    assert_eq!(t.model.encoder, EncoderChoice::Vae, "paper uses the VAE");
    f.hints.style_suffix = false;
    f.hints.sds_guidance = 12.0;
    let t = resolve(&PlanRequest::text(" a cat "), Some(&f), &Limits::default())
        .unwrap()
        .text
        .unwrap();
    assert_eq!(t.prompt, "a cat");
    assert_eq!(t.sds.unwrap().guidance, 12.0);
}

#[test]
fn plans_round_trip_through_json_and_key_their_checkpoints() {
    let p = resolve(
        &PlanRequest::text("a crown"),
        Some(&facts(true)),
        &Limits::default(),
    )
    .unwrap();
    let back: RunPlan = serde_json::from_str(&serde_json::to_string(&p).unwrap()).unwrap();
    assert_eq!(back, p);
    // A plan stored before `retrieval_share` existed starts half its samples from icons, as it
    // did then.
    let mut old = serde_json::to_value(&p).unwrap();
    let sample = &mut old["text"]["sample"];
    assert!(
        sample
            .as_object_mut()
            .unwrap()
            .remove("retrieval_share")
            .is_some()
    );
    // ... and one stored before `lr_scale` existed ran the style's schedule as it is.
    assert!(
        old["text"]["sds"]
            .as_object_mut()
            .unwrap()
            .remove("lr_scale")
            .is_some()
    );
    let old: RunPlan = serde_json::from_value(old).unwrap();
    let old = old.text.unwrap();
    assert_eq!(old.sample.unwrap().retrieval_share, 0.5);
    assert_eq!(old.sds.unwrap().lr_scale, 1.0);
    let mut q = p.clone();
    q.text.as_mut().unwrap().paths += 1;
    assert_ne!(p.key(), q.key());
    assert_eq!(p.key(), back.key());
}

#[test]
fn the_sds_learning_rate_scale_reaches_the_plan_within_its_range() {
    let with = |lr_scale: Option<f32>| {
        resolve(
            &PlanRequest {
                tuning: Tuning {
                    lr_scale,
                    ..Tuning::default()
                },
                ..PlanRequest::text("x")
            },
            Some(&facts(true)),
            &Limits::default(),
        )
    };
    let lr = |r: Result<RunPlan, SpecError>| r.unwrap().text.unwrap().sds.unwrap().lr_scale;
    assert_eq!(lr(with(None)), 1.0);
    assert_eq!(lr(with(Some(4.0))), 4.0);
    assert_eq!(lr(with(Some(MAX_LR_SCALE))), MAX_LR_SCALE);
    for bad in [0.0, -1.0, f32::NAN, f32::INFINITY, MAX_LR_SCALE * 1.01] {
        let e = with(Some(bad)).unwrap_err();
        assert_eq!(e.field, "lr_scale", "{bad}: {e}");
    }
}

fn wide(req: PlanRequest) -> PlanRequest {
    PlanRequest {
        canvas: CanvasRequest {
            aspect: Some(crate::pipeline::Aspect::Wide16x9),
            ..CanvasRequest::default()
        },
        ..req
    }
}

#[test]
fn a_canvas_resolves_once_into_the_plan() {
    // Nothing asked: no canvas in the plan or its JSON (stored plans and SVGs as before).
    let t = text(PlanRequest::text("a crown"), false);
    assert_eq!(t.canvas, None);
    assert_eq!(t.sample_dims(), (t.size, t.size));
    let json = serde_json::to_value(&t).unwrap();
    assert!(json.get("canvas").is_none() && json.get("negative_prompt").is_none());
    // Stable Diffusion (balanced, 256 px) samples at the aspect; the SVG is exactly 16:9.
    let t = text(wide(PlanRequest::text("a crown")), false);
    let c = t.canvas.unwrap();
    assert_eq!(
        (c.width, c.height, c.sample_width, c.sample_height),
        (464, 261, 448, 256)
    );
    assert_eq!((t.sample_dims(), t.canvas_dims()), ((448, 256), (464, 261)));
    // The small prior draws its 64 px square on a 16:9 canvas.
    let t = text(wide(PlanRequest::text("a crown")), true);
    assert_eq!((t.sample_dims(), t.canvas_dims()), ((64, 64), (128, 72)));
    // From scratch, augmentation crops the sample's shape from a larger render.
    let t = text(
        wide(PlanRequest {
            method: Method::Scratch,
            preset: Preset::Fast,
            ..PlanRequest::text("a crown")
        }),
        false,
    );
    let aug = t.sds_config().unwrap().augment.unwrap();
    assert_eq!(t.sample_dims(), (128, 64));
    assert_eq!((aug.out_dims(), aug.render_dims()), ((128, 64), (150, 75)));
}

#[test]
fn bad_canvases_and_negative_prompts_name_their_field() {
    let err = |req: PlanRequest, f: &ModelFacts| {
        resolve(&req, Some(f), &Limits::default())
            .unwrap_err()
            .field
    };
    let sd = facts(false);
    let both = PlanRequest {
        canvas: CanvasRequest {
            width: Some(640),
            height: Some(360),
            ..wide(PlanRequest::text("x")).canvas
        },
        ..PlanRequest::text("x")
    };
    assert_eq!(err(both, &sd), "width");
    let size = |w, h| PlanRequest {
        canvas: CanvasRequest {
            aspect: None,
            width: Some(w),
            height: Some(h),
        },
        ..PlanRequest::text("x")
    };
    assert_eq!(err(size(64, 2049), &sd), "height");
    assert_eq!(err(size(10, 100), &sd), "width");
    let t = text(size(1920, 1080), false);
    assert_eq!(t.canvas_dims(), (1920, 1080));
    assert_eq!(t.sample_dims(), (448, 256));
    let neg = |n: &str| PlanRequest {
        negative_prompt: Some(n.into()),
        ..PlanRequest::text("x")
    };
    assert_eq!(err(neg(""), &sd), "negative_prompt");
    assert_eq!(err(neg(&"x".repeat(1001)), &sd), "negative_prompt");
    assert_eq!(err(neg("a\u{7}b"), &sd), "negative_prompt");
    // The analytic test teacher has no unconditional branch to put it in.
    assert_eq!(
        err(neg("blurry"), &ModelFacts::paper("test")),
        "negative_prompt"
    );
    let t = text(neg("blurry"), true);
    assert_eq!(t.negative_prompt.as_deref(), Some("blurry"));
    assert_eq!(t.sds_config().unwrap().negative_prompt, "blurry");
    assert_eq!(
        text(PlanRequest::text("x"), true)
            .sds_config()
            .unwrap()
            .negative_prompt,
        ""
    );
}

#[test]
fn a_caption_colour_is_resolved_into_the_plan_with_the_models_steering() {
    let mut steered = facts(true);
    steered.hints.colour_steer = crate::caption::ColourSteer::Svg;
    let plan = |caption: &str, method, facts: &ModelFacts| {
        let req = PlanRequest {
            method,
            ..PlanRequest::text(caption)
        };
        resolve(&req, Some(facts), &Limits::default())
            .unwrap()
            .text
            .unwrap()
    };
    let t = plan("a blue cat", Method::SdLiveSds, &steered);
    let c = t.caption.as_ref().unwrap();
    assert_eq!(c.colour().map(|c| c.hue), Some(crate::caption::Hue::Blue));
    assert_eq!(c.objects[0].words, "cat");
    assert_eq!(c.steer, crate::caption::ColourSteer::Svg);
    // A caption of one uncoloured thing has none, and its plan's JSON is as before.
    let t = plan("a crown", Method::SdLiveSds, &steered);
    assert_eq!(t.caption, None);
    assert!(!serde_json::to_string(&t).unwrap().contains("\"caption\""));
    // Stable Diffusion reads colours itself: parsed, not steered. A run that samples nothing
    // has nothing to steer.
    let t = plan("a blue cat", Method::SdLiveSds, &facts(false));
    assert_eq!(t.caption.unwrap().steer, crate::caption::ColourSteer::Off);
    assert_eq!(plan("a blue cat", Method::Scratch, &steered).caption, None);
}
