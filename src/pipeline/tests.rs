use super::*;
use crate::progress::CancelToken;
use std::path::{Path, PathBuf};

fn spec() -> JobSpec {
    JobSpec {
        kind: JobKind::Vectorize,
        caption: None,
        image: Some(vec![1, 2, 3]),
        svg: None,
        style: Style::Iconography,
        method: Method::SdLiveSds,
        paths: Some(16),
        steps: Some(100),
        seed: MAX_SEED,
        samples: Some(4),
        preset: Preset::Balanced,
        priority: 0,
        retrieval: true,
        vector: Default::default(),
        canvas: Default::default(),
        negative_prompt: None,
        size_conditioning: None,
        plan: None,
        variations: None,
    }
}

#[test]
fn spec_roundtrips_through_json_with_base64_image() {
    let s = spec();
    let json = serde_json::to_string(&s).unwrap();
    assert!(json.contains("\"image\":\"AQID\""));
    let back: JobSpec = serde_json::from_str(&json).unwrap();
    assert_eq!(back, s);
}

#[test]
fn validation_names_the_field() {
    let l = Limits::default();
    assert!(spec().validate(&l).is_ok());
    let mut s = spec();
    s.paths = Some(0);
    assert_eq!(s.validate(&l).unwrap_err().field, "paths");
    // Seeds stay within what JavaScript clients keep exactly.
    let mut s = spec();
    s.seed = MAX_SEED;
    assert!(s.validate(&l).is_ok());
    s.seed = MAX_SEED + 1;
    assert_eq!(s.validate(&l).unwrap_err().field, "seed");
    assert!(parse_seed("9007199254740992").is_err());
    assert_eq!(parse_seed("9007199254740991"), Ok(MAX_SEED));
    let mut s = spec();
    s.image = None;
    assert_eq!(s.validate(&l).unwrap_err().field, "image");
    let mut s = spec();
    s.kind = JobKind::Text;
    s.image = None;
    assert_eq!(s.validate(&l).unwrap_err().field, "caption");
    s.caption = Some("自転車".into());
    assert!(s.validate(&l).is_ok());
    s.priority = 1000;
    assert_eq!(s.validate(&l).unwrap_err().field, "priority");
}

/// A fresh temp directory for one test.
fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vf-pipeline-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A stand-in model directory (only what the resolution looks at).
fn fake_model(dir: &Path, pixel: bool, scorer: bool) {
    std::fs::create_dir_all(dir.join("unet")).unwrap();
    std::fs::write(dir.join("unet/config.json"), "{}").unwrap();
    if !pixel {
        std::fs::create_dir_all(dir.join("vae")).unwrap();
    }
    if scorer {
        std::fs::create_dir_all(dir.join("scorer")).unwrap();
        std::fs::write(dir.join("scorer/config.json"), "{}").unwrap();
    }
}

#[test]
fn default_model_resolution_order() {
    let root = tmp("default-model");
    let (cwd, crate_root, env) = (root.join("cwd"), root.join("crate"), root.join("env"));
    for d in [&cwd, &crate_root] {
        std::fs::create_dir_all(d).unwrap();
    }
    // nothing anywhere
    assert_eq!(
        resolve_default_model(None, Some(&cwd), &crate_root),
        Ok(None)
    );
    // the crate root's copy is found from any working directory
    fake_model(&crate_root.join(EMBEDDED_MODEL), true, true);
    assert_eq!(
        resolve_default_model(None, Some(&cwd), &crate_root),
        Ok(Some(crate_root.join(EMBEDDED_MODEL)))
    );
    assert_eq!(
        resolve_default_model(None, None, &crate_root),
        Ok(Some(crate_root.join(EMBEDDED_MODEL)))
    );
    // the working directory's copy wins over the crate root's
    fake_model(&cwd.join(EMBEDDED_MODEL), true, false);
    assert_eq!(
        resolve_default_model(None, Some(&cwd), &crate_root),
        Ok(Some(cwd.join(EMBEDDED_MODEL)))
    );
    // the environment variable wins over both; a bad value is an error, an empty one unset
    fake_model(&env, false, false);
    assert_eq!(
        resolve_default_model(Some(env.as_os_str()), Some(&cwd), &crate_root),
        Ok(Some(env.clone()))
    );
    let missing = root.join("missing");
    let e = resolve_default_model(Some(missing.as_os_str()), Some(&cwd), &crate_root)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(DEFAULT_MODEL_ENV) && e.contains("missing"),
        "{e}"
    );
    assert_eq!(
        resolve_default_model(Some(std::ffi::OsStr::new("")), Some(&cwd), &crate_root),
        Ok(Some(cwd.join(EMBEDDED_MODEL)))
    );
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn default_model_fills_unconfigured_dirs_and_passes_the_submit_check() {
    let root = tmp("default-dirs");
    let model = root.join("vf-icon");
    fake_model(&model, true, true);
    let dirs = ModelDirs::default().or_default_model(Some(model.clone()));
    assert_eq!(dirs.sd_dir.as_deref(), Some(model.as_path()));
    assert_eq!(dirs.clip_dir, Some(model.join("scorer")));
    assert!(dirs.is_small_prior());
    assert!(DefaultExecutor::new(dirs.clone()).text_ready().is_ok());
    // the pixel-space presets apply to its plans
    let e = DefaultExecutor::new(dirs);
    let plan = e
        .plan(&PlanRequest::text("a crown"), &Limits::default())
        .unwrap()
        .text
        .unwrap();
    assert!(plan.model.small_prior);
    assert_eq!(plan.size, Preset::Balanced.settings_for(true).size);
    assert_ne!(plan.size, Preset::Balanced.settings().size);
    // configured models are kept; a configured scorer is not replaced
    let sd = root.join("sd");
    fake_model(&sd, false, false);
    let configured = ModelDirs {
        sd_dir: Some(sd.clone()),
        ..ModelDirs::default()
    };
    assert_eq!(
        configured.clone().or_default_model(Some(model.clone())),
        configured
    );
    let with_clip = ModelDirs {
        clip_dir: Some(root.join("clip")),
        ..ModelDirs::default()
    }
    .or_default_model(Some(model.clone()));
    assert_eq!(with_clip.clip_dir, Some(root.join("clip")));
    assert_eq!(with_clip.sd_dir, Some(model.clone()));
    // a text_encoder/ folder without weights (the embedded model before its MiniLM weights
    // are fetched) is refused at submit time with a pointer to the docs
    std::fs::create_dir_all(model.join("text_encoder")).unwrap();
    let dirs = ModelDirs::default().or_default_model(Some(model.clone()));
    let msg = DefaultExecutor::new(dirs.clone())
        .text_ready()
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("MiniLM") && msg.contains("EMBEDDED.md"),
        "{msg}"
    );
    std::fs::write(model.join("text_encoder/model.safetensors"), b"x").unwrap();
    assert!(DefaultExecutor::new(dirs).text_ready().is_ok());
    // absent default: still the configuration hint
    let none = ModelDirs::default().or_default_model(None);
    let msg = DefaultExecutor::new(none)
        .text_ready()
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("sd_dir") && msg.contains(EMBEDDED_MODEL),
        "{msg}"
    );
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn encoder_choice_resolution() {
    let root = tmp("encoder");
    let sd = root.join("sd");
    fake_model(&sd, false, false);
    let taesd = root.join("my-taesd");
    let r = |c, prefer, conf: Option<&Path>| resolve_encoder(c, prefer, &sd, conf);
    assert_eq!(r(EncoderChoice::Vae, true, Some(&taesd)).unwrap(), None);
    assert_eq!(r(EncoderChoice::Auto, true, None).unwrap(), None);
    let e = r(EncoderChoice::Taesd, true, None).unwrap_err();
    assert!(matches!(e, PipelineError::InvalidInput(_)) && e.to_string().contains("--taesd"));
    assert_eq!(
        r(EncoderChoice::Taesd, false, Some(&taesd)).unwrap(),
        Some(taesd.clone())
    );
    assert_eq!(
        r(EncoderChoice::Auto, true, Some(&taesd)).unwrap(),
        Some(taesd)
    );
    assert_eq!(r(EncoderChoice::Auto, false, None).unwrap(), None);
    // a taesd/ folder beside the model is found; one inside wins
    std::fs::create_dir_all(root.join("taesd")).unwrap();
    std::fs::write(root.join("taesd/config.json"), "{}").unwrap();
    assert_eq!(
        r(EncoderChoice::Auto, true, None).unwrap(),
        Some(root.join("taesd"))
    );
    std::fs::create_dir_all(sd.join("taesd")).unwrap();
    std::fs::write(sd.join("taesd/config.json"), "{}").unwrap();
    assert_eq!(
        r(EncoderChoice::Taesd, true, None).unwrap(),
        Some(sd.join("taesd"))
    );
    assert_eq!(
        r(EncoderChoice::Auto, false, None).unwrap(),
        None,
        "paper keeps the VAE"
    );
    // pixel-space models have no encoder to choose
    let px = root.join("px");
    fake_model(&px, true, false);
    assert_eq!(
        resolve_encoder(EncoderChoice::Taesd, true, &px, None).unwrap(),
        None
    );
    assert_eq!("TAESD".parse::<EncoderChoice>(), Ok(EncoderChoice::Taesd));
    assert!("fast".parse::<EncoderChoice>().is_err());
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn pixel_presets_suit_a_small_prior() {
    for p in Preset::ALL {
        let (sd, px) = (p.settings(), p.settings_for(true));
        assert_eq!(
            sd.trace_size, sd.size,
            "{p:?}: SD traces at the teacher size"
        );
        assert_eq!(px.size, 64, "{p:?}: the small prior's image side");
        assert!((64..=256).contains(&px.trace_size), "{p:?}");
        assert!(px.steps <= sd.steps.max(20), "{p:?}");
        assert!(!px.prefer_taesd);
    }
    let b = Preset::default().settings_for(true);
    assert_eq!((b.size, b.trace_size), (64, 128));
}

#[test]
fn default_executor_refuses_text_with_configuration_hint() {
    let e = DefaultExecutor::default();
    let msg = e.text_ready().unwrap_err().to_string();
    assert!(msg.contains("sd_dir"), "{msg}");
    let ctx = JobContext::detached(CancelToken::new());
    // The spec's image bytes are not an image: a clear input error, not a panic.
    let err = e.run(&spec(), &ctx).unwrap_err();
    assert!(matches!(err, PipelineError::Image(_)), "{err}");
    assert_eq!(err.code(), crate::pipeline::FailureCode::InvalidInput);
}
