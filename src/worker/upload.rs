//! A claimed job's upload, read back from its own table (`store::uploads`): the stored spec holds
//! "" markers where the image and the starting SVG were. The image comes back as the bytes the
//! submit decoded (no base64 on the way).

use crate::pipeline::JobSpec;
use crate::store::{Store, StoreError};
use base64::Engine as _;
use tokio::runtime::Handle;

/// Why a claimed job's upload could not be put back.
#[derive(Debug, PartialEq)]
pub(super) enum AttachError {
    /// The database could not be read (a connection lost, a busy lock): worth another attempt.
    Store(String),
    /// The upload is gone or malformed: no attempt will do better.
    Invalid(String),
}

impl AttachError {
    /// A failed read of the upload: the database itself (retryable), or what it returned.
    fn from_store(e: StoreError) -> AttachError {
        match e {
            StoreError::Db(_) => {
                AttachError::Store(format!("reading the job's upload failed: {e}"))
            }
            e => AttachError::Invalid(format!("the job's upload is unreadable: {e}")),
        }
    }
}

impl From<&str> for AttachError {
    fn from(msg: &str) -> Self {
        AttachError::Invalid(msg.to_string())
    }
}

/// Puts the stored upload back into `spec`. A spec without markers is left as it is (a job
/// stored before uploads had their own table carries its upload inline). Errors name what is
/// missing or unreadable.
pub(super) fn attach(
    store: &Store,
    runtime: &Handle,
    job_id: &str,
    spec: &mut JobSpec,
) -> Result<(), AttachError> {
    let wants_image = spec.image.as_ref().is_some_and(Vec::is_empty);
    let wants_svg = spec.svg.as_ref().is_some_and(String::is_empty);
    if !wants_image && !wants_svg {
        return Ok(());
    }
    let up = runtime
        .block_on(store.upload(job_id))
        .map_err(AttachError::from_store)?
        .ok_or("the job's upload is no longer stored")?;
    if wants_image {
        spec.image = Some(match (up.image_bytes, up.image_base64) {
            (Some(bytes), _) => bytes,
            // Stored by an older version (a job queued across the upgrade).
            (None, Some(b64)) => base64::engine::general_purpose::STANDARD
                .decode(b64.as_bytes())
                .map_err(|e| {
                    AttachError::Invalid(format!("the job's stored image is not base64: {e}"))
                })?,
            (None, None) => return Err("the job's stored upload has no image".into()),
        });
    }
    if wants_svg {
        spec.svg = Some(up.svg.ok_or("the job's stored upload has no SVG")?);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::{JobKind, NewJob, NewUpload};

    /// A stored vectorize spec whose image is in `uploads` (the "" marker).
    fn marked_spec() -> JobSpec {
        serde_json::from_str(
            r#"{"kind": "vectorize", "caption": null, "image": "", "svg": null,
                "style": "iconography", "method": "sd_live_sds", "paths": 4, "steps": 2,
                "seed": 1, "samples": 1, "preset": "balanced", "priority": 0}"#,
        )
        .unwrap()
    }

    #[test]
    fn a_database_error_is_retryable_a_missing_upload_is_not() {
        let rt = tokio::runtime::Runtime::new().unwrap();
        let dir = tempfile::tempdir().unwrap();
        let store = rt
            .block_on(Store::open(&dir.path().join("jobs.db"), 2))
            .unwrap();
        let job = |id: &str, upload| NewJob {
            upload,
            ..NewJob::new(id, JobKind::Vectorize, "{}")
        };
        let up = NewUpload {
            image: Some(vec![1, 2, 3]),
            svg: None,
            max_total_bytes: 1 << 20,
            max_tenant_bytes: 0,
        };
        rt.block_on(store.insert_job(&job("with", Some(up)), 1))
            .unwrap();
        rt.block_on(store.insert_job(&job("without", None), 1))
            .unwrap();

        let mut spec = marked_spec();
        attach(&store, rt.handle(), "with", &mut spec).unwrap();
        assert_eq!(spec.image, Some(vec![1, 2, 3]));

        // An upload an older version stored as base64 still reads.
        rt.block_on(
            sqlx::query(
                "UPDATE uploads SET image_bytes = NULL, image = 'AQIE' WHERE job_id = 'with'",
            )
            .execute(store.pool()),
        )
        .unwrap();
        let mut spec = marked_spec();
        attach(&store, rt.handle(), "with", &mut spec).unwrap();
        assert_eq!(spec.image, Some(vec![1, 2, 4]));

        let mut spec = marked_spec();
        let err = attach(&store, rt.handle(), "without", &mut spec).unwrap_err();
        assert!(matches!(err, AttachError::Invalid(_)), "{err:?}");

        // The database goes away under the worker: another attempt may succeed.
        rt.block_on(store.close());
        let mut spec = marked_spec();
        let err = attach(&store, rt.handle(), "with", &mut spec).unwrap_err();
        assert!(matches!(err, AttachError::Store(_)), "{err:?}");
    }
}
