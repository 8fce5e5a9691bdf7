//! Uploads, stored apart from the job row (`migrations/*/0005_uploads.sql`, `0001` on PostgreSQL): written once at
//! submit, read once per claim, deleted when the job finishes. An image is stored as its bytes
//! (`0006_upload_bytes.sql`, `0002` on PostgreSQL): the API's base64 is decoded once, at submit.

use super::{Store, StoreError, sql};

/// A new job's upload and the quotas its insert must respect.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NewUpload {
    /// The image file's bytes (PNG or JPEG).
    pub image: Option<Vec<u8>>,
    pub svg: Option<String>,
    /// All stored uploads together may hold at most this many bytes.
    pub max_total_bytes: i64,
    /// The submitting tenant's stored uploads at most this many bytes; 0: no cap of its own.
    pub max_tenant_bytes: i64,
}

impl NewUpload {
    /// Bytes it takes in the store.
    pub fn bytes(&self) -> i64 {
        let n = self.image.as_ref().map_or(0, Vec::len) + self.svg.as_ref().map_or(0, String::len);
        i64::try_from(n).unwrap_or(i64::MAX)
    }
}

/// A stored upload, as the worker reads it back.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct UploadRow {
    /// The image file's bytes.
    pub image_bytes: Option<Vec<u8>>,
    /// The image as base64: only uploads older versions stored (jobs queued across an upgrade).
    pub image_base64: Option<String>,
    pub svg: Option<String>,
}

impl Store {
    /// The upload of a job not yet finished (`None` once it finished, or when it had none).
    pub async fn upload(&self, job_id: &str) -> Result<Option<UploadRow>, StoreError> {
        Ok(sqlx::query_as(sql!("get_upload.sql"))
            .bind(job_id)
            .fetch_optional(&self.pool)
            .await?)
    }

    /// Bytes of stored uploads: all of them (`tenant` `None`), or one tenant's
    /// (`Some(None)`: the operator's).
    pub async fn upload_bytes(&self, tenant: Option<Option<&str>>) -> Result<i64, StoreError> {
        Ok(sqlx::query_scalar(sql!(self, "upload_bytes.sql"))
            .bind(i64::from(tenant.is_some()))
            .bind(tenant.flatten())
            .fetch_one(&self.pool)
            .await?)
    }
}
