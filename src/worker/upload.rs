//! A claimed job's upload, read back from its own table (`store::uploads`): the stored spec holds
//! "" markers where the image and the starting SVG were.

use crate::pipeline::JobSpec;
use crate::store::Store;
use base64::Engine as _;
use tokio::runtime::Handle;

/// Puts the stored upload back into `spec`. A spec without markers is left as it is (a job
/// stored before uploads had their own table carries its upload inline). Errors name what is
/// missing or unreadable.
pub(super) fn attach(
    store: &Store,
    runtime: &Handle,
    job_id: &str,
    spec: &mut JobSpec,
) -> Result<(), String> {
    let wants_image = spec.image.as_ref().is_some_and(Vec::is_empty);
    let wants_svg = spec.svg.as_ref().is_some_and(String::is_empty);
    if !wants_image && !wants_svg {
        return Ok(());
    }
    let up = runtime
        .block_on(store.upload(job_id))
        .map_err(|e| format!("reading the job's upload failed: {e}"))?
        .ok_or("the job's upload is no longer stored")?;
    if wants_image {
        let b64 = up.image.ok_or("the job's stored upload has no image")?;
        let bytes = base64::engine::general_purpose::STANDARD
            .decode(b64.as_bytes())
            .map_err(|e| format!("the job's stored image is not base64: {e}"))?;
        spec.image = Some(bytes);
    }
    if wants_svg {
        spec.svg = Some(up.svg.ok_or("the job's stored upload has no SVG")?);
    }
    Ok(())
}
