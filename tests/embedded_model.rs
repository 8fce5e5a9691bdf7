//! The shipped embedded model (`models/vf-icon/`) against reference outputs of the same exported
//! files in PyTorch (`scripts/embedded/make_refs.py` → `tests/fixtures/vf-icon-refs/`): the UNet,
//! the autoencoder (latent model) and the IconClip image tower always; the MiniLM conditioning,
//! the scorer's text tower and a retrieval run when the MiniLM weights and the retrieval index
//! are installed (`vectorfusion setup`; CI runs it).

mod common;
use common::max_abs;

use candle_core::{DType, Device, Tensor};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use vectorfusion::models::bert::weights::MiniLmLocations;
use vectorfusion::models::codec::Codec;
use vectorfusion::models::scheduler::{Sampler, SamplerKind, SchedulerConfig};
use vectorfusion::models::scorer::{IconClip, IconClipConfig, IconClipScorer, ImageTextScorer};
use vectorfusion::models::stable_diffusion::{load_unet, load_vae};
use vectorfusion::models::{LoadOptions, Precision, StableDiffusion};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/vf-icon")
}

fn refs() -> (std::collections::HashMap<String, Tensor>, serde_json::Value) {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/vf-icon-refs/refs.safetensors");
    let bytes = std::fs::read(&path).unwrap();
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + n]).unwrap();
    let meta = header["__metadata__"].clone();
    (
        candle_core::safetensors::load(&path, &Device::Cpu).unwrap(),
        meta,
    )
}

fn sha256(path: &Path) -> String {
    format!("{:x}", Sha256::digest(std::fs::read(path).unwrap()))
}

/// The fixture was made from exactly the committed weights (re-run make_refs.py after a retrain).
#[test]
fn reference_fixture_matches_the_committed_weights() {
    let (_, meta) = refs();
    let unet = root().join("unet/diffusion_pytorch_model.safetensors");
    let scorer = root().join("scorer/model.safetensors");
    assert_eq!(
        meta["model_sha256_unet"].as_str(),
        Some(sha256(&unet).as_str()),
        "stale refs: run scripts/embedded/make_refs.py"
    );
    assert_eq!(
        meta["model_sha256_scorer"].as_str(),
        Some(sha256(&scorer).as_str()),
        "stale refs: run scripts/embedded/make_refs.py"
    );
    let vae = root().join("vae/diffusion_pytorch_model.safetensors");
    if vae.is_file() {
        assert_eq!(
            meta["model_sha256_vae"].as_str(),
            Some(sha256(&vae).as_str()),
            "stale refs: run scripts/embedded/make_refs.py"
        );
    }
}

/// The latent model's autoencoder: encode (scaled posterior mean) and decode as diffusers.
#[test]
fn autoencoder_matches_diffusers_on_the_shipped_weights() {
    let dir = root().join("vae");
    if !dir.is_dir() {
        assert!(vectorfusion::models::codec::is_pixel_space(&root()).unwrap());
        return;
    }
    let (r, _) = refs();
    let vae = load_vae(&dir, Precision::F32, &Device::Cpu).unwrap();
    let codec = Codec::from(vae);
    assert_eq!(codec.latent_side(64), Ok(16));
    let z = codec.encode(&r["vae_image"]).unwrap();
    let d = max_abs(&z, &r["vae_latent"]);
    assert!(d < 1e-3, "VAE latents max abs diff {d}");
    let x = codec.decode(&r["ddim_step3"]).unwrap();
    let d = max_abs(&x, &r["vae_decoded"]);
    assert!(d < 1e-3, "VAE decode max abs diff {d}");
}

#[test]
fn unet_matches_diffusers_on_the_shipped_weights() {
    let (r, _) = refs();
    let unet = load_unet(&root().join("unet"), Precision::F32, &Device::Cpu).unwrap();
    let cond = r["unet_cond"].narrow(0, 0, 1).unwrap();
    let eps = unet.forward(&r["unet_x_t"], 500.0, &cond).unwrap();
    let d = max_abs(&eps, &r["unet_eps"]);
    assert!(d < 2e-4, "UNet eps max abs diff {d}");
}

/// The shipped scheduler (prediction type, trailing spacing, `clip_sample`) drives a guided DDIM
/// trajectory exactly as diffusers' `DDIMScheduler` does.
#[test]
fn guided_ddim_with_the_shipped_scheduler_matches_diffusers() {
    let (r, meta) = refs();
    let g: f64 = meta["ddim_guidance"].as_str().unwrap().parse().unwrap();
    let unet = load_unet(&root().join("unet"), Precision::F32, &Device::Cpu).unwrap();
    let text = std::fs::read_to_string(root().join("scheduler/scheduler_config.json")).unwrap();
    let cfg: SchedulerConfig = serde_json::from_str(&text).unwrap();
    let sampler = Sampler::new(&cfg, SamplerKind::Ddim, 4).unwrap();
    let want_t: Vec<i64> = r["ddim_timesteps"].to_vec1().unwrap();
    let got_t: Vec<i64> = sampler.timesteps.iter().map(|&t| t as i64).collect();
    assert_eq!(got_t, want_t);
    let cond = r["unet_cond"].narrow(0, 0, 1).unwrap();
    let uncond = &r["ddim_uncond"];
    let trajectory = |s: &Sampler| {
        let mut x = r["ddim_init"].clone();
        let mut out = Vec::new();
        for (i, &t) in s.timesteps.iter().enumerate() {
            let eu = unet.forward(&x, t, uncond).unwrap();
            let ec = unet.forward(&x, t, &cond).unwrap();
            let guided = (&eu + ((ec - &eu).unwrap() * g).unwrap()).unwrap();
            x = s.step(&guided, i, &x, None).unwrap();
            out.push(x.clone());
        }
        out
    };
    for (i, x) in trajectory(&sampler).iter().enumerate() {
        let d = max_abs(x, &r[&format!("ddim_step{i}")]);
        assert!(d < 1e-3, "DDIM step {i}: max abs diff {d}");
    }
    // The shipped config's clip_sample matters here: without it the trajectory differs.
    if cfg.clip_sample {
        let unclipped = SchedulerConfig {
            clip_sample: false,
            ..cfg.clone()
        };
        let s = Sampler::new(&unclipped, SamplerKind::Ddim, 4).unwrap();
        let last = trajectory(&s).pop().unwrap();
        let d = max_abs(&last, &r["ddim_step3"]);
        assert!(d > 1e-3, "clip_sample had no effect (diff {d})");
    }
}

#[test]
fn iconclip_image_tower_matches_torch_on_the_shipped_weights() {
    let (r, _) = refs();
    let dir = root().join("scorer");
    let cfg = IconClipConfig::from_file(&dir.join("config.json")).unwrap();
    let w = dir.join("model.safetensors");
    let vb =
        unsafe { candle_nn::VarBuilder::from_mmaped_safetensors(&[w], DType::F32, &Device::Cpu) }
            .unwrap();
    let m = IconClip::new(vb, cfg, 384).unwrap();
    let emb = m.encode_image(&r["clip_images"]).unwrap();
    let d = max_abs(&emb, &r["clip_image_emb"]);
    assert!(d < 1e-4, "image embeddings max abs diff {d}");
}

/// MiniLM conditioning of the pixel UNet and the scorer's text tower, end to end through the
/// loaders the pipeline uses.
#[test]
fn text_conditioning_and_scorer_text_match_when_minilm_is_installed() {
    if let Err(e) = MiniLmLocations::from_env().ensure(false) {
        common::skip(
            "text_conditioning_and_scorer_text_match_when_minilm_is_installed",
            &e.to_string(),
        );
        return;
    }
    let (r, meta) = refs();
    let captions: Vec<String> = serde_json::from_str(meta["captions"].as_str().unwrap()).unwrap();
    let sd = StableDiffusion::load(&root(), &LoadOptions::default()).unwrap();
    for (i, c) in captions.iter().enumerate() {
        let cond = sd.embed_text(c).unwrap();
        let want = r["unet_cond"].narrow(0, i, 1).unwrap();
        // relative to the largest activation (|h| reaches ~10 at padded positions)
        let scale = max_abs(&want, &want.zeros_like().unwrap()).max(1.0);
        let d = max_abs(&cond, &want);
        assert!(
            d < 1e-4 * scale,
            "conditioning of {c:?}: max abs diff {d} (scale {scale})"
        );
    }
    let s = IconClipScorer::load(&root().join("scorer"), &root(), &Device::Cpu, false).unwrap();
    let caps: Vec<&str> = captions.iter().map(String::as_str).collect();
    let t = s.text_embeddings(&caps).unwrap();
    let t = Tensor::from_vec(t.concat(), (caps.len(), t[0].len()), &Device::Cpu).unwrap();
    let d = max_abs(&t, &r["clip_text_emb"]);
    assert!(d < 1e-4, "scorer text embeddings max abs diff {d}");
}

/// `generate` on the embedded model with the installed retrieval index: half the samples start
/// from training icons, the result names them (set, name, licence), and `retrieval: false`
/// samples from noise only.
#[test]
fn retrieval_names_its_source_icons_when_the_index_is_installed() {
    use vectorfusion::pipeline::{Method, PlanRequest, Preset};
    use vectorfusion::retrieval::RetrievalLocations;
    if let Err(e) = MiniLmLocations::from_env().ensure(false) {
        common::skip(
            "retrieval_names_its_source_icons_when_the_index_is_installed",
            &e.to_string(),
        );
        return;
    }
    if let Err(e) = RetrievalLocations::from_env().load(&root()) {
        common::skip(
            "retrieval_names_its_source_icons_when_the_index_is_installed",
            &e.to_string(),
        );
        return;
    }
    let m = common::runs::executor(root(), Some(root().join("scorer")));
    assert!(m.small_prior());
    let req = PlanRequest {
        method: Method::SdLive,
        preset: Preset::Draft,
        paths: Some(8),
        steps: Some(2),
        samples: Some(2),
        seed: 3,
        ..PlanRequest::text("red heart")
    };
    let plan = common::runs::plan(&m, &req);
    let models = m.load_models(plan.text.as_ref().unwrap()).unwrap();
    let index = models.retrieval.as_ref().unwrap();
    use vectorfusion::stages::sample::{RetrievalPick, retrieve};
    let pick = |n, per_caption| RetrievalPick {
        n,
        per_caption,
        seed: 0,
    };
    let hits = retrieve(models.teacher(), index, "red heart", pick(2, 1)).unwrap();
    assert_eq!(hits.len(), 2);
    assert!(hits[0].0.icon.caption.contains("heart"), "{:?}", hits[0].0);
    assert!(!vectorfusion::retrieval::is_held_out(&hits[0].0.icon.set));
    assert_eq!((hits[0].1.width, hits[0].1.height), (64, 64));
    // One drawing per caption: two captions; two per caption: two artists' drawings of one.
    assert_ne!(hits[0].0.icon.caption, hits[1].0.icon.caption);
    let same = retrieve(models.teacher(), index, "red heart", pick(2, 2)).unwrap();
    assert_eq!(same[0].0.icon.caption, same[1].0.icon.caption, "{same:?}");
    assert_ne!(same[0].0.icon, same[1].0.icon);
    let out = common::runs::run(&m, &req).unwrap();
    let detail = serde_json::to_value(&out.report).unwrap();
    let starts = detail["retrieval"]["starts"].as_array().unwrap();
    // The model's `_retrieval_share` of the two samples start from icons (one or both).
    let share = detail["retrieval"]["share"].as_f64().unwrap();
    let n = vectorfusion::stages::sample::retrieved_count(2, share);
    assert!(n >= 1);
    assert_eq!(starts.len(), n, "{}", detail);
    // `_retrieval_per_caption` reaches the sampler: two drawings of one caption when it allows.
    let per_caption = detail["retrieval"]["per_caption"].as_u64().unwrap();
    if n == 2 {
        let same = starts[0]["caption"] == starts[1]["caption"];
        assert_eq!(same, per_caption >= 2, "{}", detail);
    }
    for key in ["set", "name", "license", "caption"] {
        assert!(starts[0][key].is_string(), "{key}: {}", detail);
    }
    if detail["retrieval"]["chosen"].is_object() {
        assert!(
            out.svg.contains("<metadata>Started from the icon"),
            "{}",
            out.svg
        );
    } else {
        assert!(!out.svg.contains("<metadata>"));
    }
    let off = common::runs::run(
        &m,
        &PlanRequest {
            retrieval: false,
            ..req
        },
    )
    .unwrap();
    let retrieval = off.report.retrieval.unwrap();
    assert!(retrieval.starts.is_empty());
    assert_eq!(retrieval.unavailable.as_deref(), Some("turned off"));
}
