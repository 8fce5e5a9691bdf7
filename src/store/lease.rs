//! The worker's side of the store: claiming jobs and every write fenced by the lease
//! (`(lease_owner, attempts)`): heartbeats, progress, checkpoints, snapshots, and the outcome.

use super::{AttemptOutcome, FailureCode, Heartbeat, JobRow, Lease, Store, StoreError, sql};

impl Store {
    /// Finishes running jobs whose lease expired and that cannot be retried; returns them.
    pub async fn reap_expired(&self, now: i64) -> Result<Vec<JobRow>, StoreError> {
        let rows: Vec<JobRow> = sqlx::query_as(sql!("reap_expired.sql"))
            .bind(now)
            .fetch_all(&self.writer)
            .await?;
        for row in &rows {
            self.hint_job(&row.id);
            sqlx::query(sql!("mark_lost_attempts.sql"))
                .bind(&row.id)
                .bind(i64::MAX)
                .bind(now)
                .execute(&self.writer)
                .await?;
        }
        Ok(rows)
    }

    /// Atomically claims the next job for `worker`, with a lease of `lease_ms`. One statement:
    /// the trigger `jobs_claim_opens_attempt` (`migrations/sqlite/0002`, `migrations/postgres/0001`)
    /// opens the attempt row (and marks earlier running attempts lost) inside it.
    pub async fn claim(
        &self,
        worker: &str,
        now: i64,
        lease_ms: i64,
    ) -> Result<Option<(JobRow, Lease)>, StoreError> {
        let row: Option<JobRow> = sqlx::query_as(sql!(self, "claim.sql"))
            .bind(worker)
            .bind(now)
            .bind(lease_ms)
            .fetch_optional(&self.lease_writer)
            .await?;
        if let Some(row) = &row {
            self.hint_job(&row.id);
        }
        Ok(row.map(|row| {
            let lease = Lease {
                job_id: row.id.clone(),
                worker: worker.to_string(),
                attempt: row.attempts,
            };
            (row, lease)
        }))
    }

    pub async fn heartbeat(
        &self,
        lease: &Lease,
        now: i64,
        lease_ms: i64,
    ) -> Result<Heartbeat, StoreError> {
        let flag: Option<i64> = sqlx::query_scalar(sql!(self, "heartbeat.sql"))
            .bind(&lease.job_id)
            .bind(&lease.worker)
            .bind(lease.attempt)
            .bind(now)
            .bind(lease_ms)
            .fetch_optional(&self.lease_writer)
            .await?;
        Ok(match flag {
            Some(c) => Heartbeat::Held { cancel: c != 0 },
            None => Heartbeat::Lost,
        })
    }

    /// Records the latest progress; `false` if the lease is gone.
    #[allow(clippy::too_many_arguments)]
    pub async fn update_progress(
        &self,
        lease: &Lease,
        stage: &str,
        step: u32,
        total: u32,
        loss: Option<f64>,
        now: i64,
    ) -> Result<bool, StoreError> {
        let r = sqlx::query(sql!("update_progress.sql"))
            .bind(&lease.job_id)
            .bind(&lease.worker)
            .bind(lease.attempt)
            .bind(stage)
            .bind(step as i64)
            .bind(total as i64)
            .bind(loss.filter(|l| l.is_finite()))
            .bind(now)
            .execute(&self.lease_writer)
            .await?;
        let held = r.rows_affected() == 1;
        if held {
            self.hint_job(&lease.job_id);
        }
        Ok(held)
    }

    /// Stores the executor's resumable state; `false` if the lease is gone.
    pub async fn save_checkpoint(
        &self,
        lease: &Lease,
        state: &str,
        now: i64,
    ) -> Result<bool, StoreError> {
        let r = sqlx::query(sql!("save_checkpoint.sql"))
            .bind(&lease.job_id)
            .bind(&lease.worker)
            .bind(lease.attempt)
            .bind(state)
            .bind(now)
            .execute(&self.lease_writer)
            .await?;
        Ok(r.rows_affected() == 1)
    }

    /// Stores a snapshot and keeps at most `keep` per job; returns its number, or `None` if
    /// the lease is gone.
    pub async fn add_snapshot(
        &self,
        lease: &Lease,
        stage: &str,
        step: u32,
        svg: &str,
        now: i64,
        keep: i64,
    ) -> Result<Option<i64>, StoreError> {
        let n: Option<i64> = sqlx::query_scalar(sql!(self, "insert_snapshot.sql"))
            .bind(&lease.job_id)
            .bind(&lease.worker)
            .bind(lease.attempt)
            .bind(stage)
            .bind(step as i64)
            .bind(svg)
            .bind(now)
            .fetch_optional(&self.lease_writer)
            .await?;
        if let Some(n) = n
            && n > keep
        {
            sqlx::query(sql!("trim_snapshots.sql"))
                .bind(&lease.job_id)
                .bind(n - keep.max(1))
                .execute(&self.lease_writer)
                .await?;
        }
        if n.is_some() {
            self.hint_job(&lease.job_id);
        }
        Ok(n)
    }

    /// Marks the job succeeded and stores its result in one transaction. `false` (and nothing
    /// written) if this lease no longer holds the job.
    pub async fn complete(
        &self,
        lease: &Lease,
        svg: &str,
        paths: i64,
        detail: &str,
        now: i64,
    ) -> Result<bool, StoreError> {
        self.complete_variations(lease, svg, paths, detail, &[], now)
            .await
    }

    /// [`Store::complete`] for a job of several results: `svg` (with `paths` and `detail`) is
    /// variation 1, `variations` the SVGs and path counts of variations 2, 3, ... (read back
    /// with [`Store::result_variation`]), all in the one transaction.
    pub async fn complete_variations(
        &self,
        lease: &Lease,
        svg: &str,
        paths: i64,
        detail: &str,
        variations: &[(&str, i64)],
        now: i64,
    ) -> Result<bool, StoreError> {
        let mut tx = self.begin().await?;
        let r = sqlx::query(sql!("complete_job.sql"))
            .bind(&lease.job_id)
            .bind(&lease.worker)
            .bind(lease.attempt)
            .bind(now)
            .execute(&mut *tx)
            .await?;
        if r.rows_affected() != 1 {
            tx.rollback().await?;
            return Ok(false);
        }
        sqlx::query(sql!("insert_result.sql"))
            .bind(&lease.job_id)
            .bind(svg)
            .bind(paths)
            .bind(detail)
            .bind(now)
            .execute(&mut *tx)
            .await?;
        for (n, (svg, paths)) in (2i64..).zip(variations) {
            sqlx::query(sql!("insert_result_variation.sql"))
                .bind(&lease.job_id)
                .bind(n)
                .bind(*svg)
                .bind(*paths)
                .execute(&mut *tx)
                .await?;
        }
        self.finish_attempt(&mut tx, lease, AttemptOutcome::Succeeded, None, now)
            .await?;
        tx.commit().await?;
        self.hint_job(&lease.job_id);
        Ok(true)
    }

    /// Records a failed attempt: re-queued at `retry_at` if given, else failed for good.
    pub async fn fail(
        &self,
        lease: &Lease,
        code: FailureCode,
        message: &str,
        retry_at: Option<i64>,
        now: i64,
    ) -> Result<Option<JobRow>, StoreError> {
        let mut tx = self.begin().await?;
        let row: Option<JobRow> = sqlx::query_as(sql!(self, "fail_job.sql"))
            .bind(&lease.job_id)
            .bind(&lease.worker)
            .bind(lease.attempt)
            .bind(retry_at)
            .bind(code)
            .bind(message)
            .bind(now)
            .fetch_optional(&mut *tx)
            .await?;
        if row.is_some() {
            let outcome = if retry_at.is_some() {
                AttemptOutcome::Retry
            } else {
                AttemptOutcome::Failed
            };
            self.finish_attempt(&mut tx, lease, outcome, Some(message), now)
                .await?;
        }
        tx.commit().await?;
        if row.is_some() {
            self.hint_job(&lease.job_id);
            if retry_at.is_some() {
                self.hint_queued();
            }
        }
        Ok(row)
    }

    /// Marks a running job cancelled (its executor stopped on request).
    pub async fn finish_cancelled(
        &self,
        lease: &Lease,
        now: i64,
    ) -> Result<Option<JobRow>, StoreError> {
        self.end_attempt(
            lease,
            sql!("finish_cancelled.sql"),
            AttemptOutcome::Cancelled,
            now,
        )
        .await
    }

    /// Hands a running job back to the queue (graceful shutdown); its checkpoint is kept.
    pub async fn release(&self, lease: &Lease, now: i64) -> Result<Option<JobRow>, StoreError> {
        self.end_attempt(
            lease,
            sql!("release_job.sql"),
            AttemptOutcome::Interrupted,
            now,
        )
        .await
    }

    async fn end_attempt(
        &self,
        lease: &Lease,
        sql: &'static str,
        outcome: AttemptOutcome,
        now: i64,
    ) -> Result<Option<JobRow>, StoreError> {
        let mut tx = self.begin().await?;
        let row: Option<JobRow> = sqlx::query_as(sql)
            .bind(&lease.job_id)
            .bind(&lease.worker)
            .bind(lease.attempt)
            .bind(now)
            .fetch_optional(&mut *tx)
            .await?;
        if row.is_some() {
            self.finish_attempt(&mut tx, lease, outcome, None, now)
                .await?;
        }
        tx.commit().await?;
        if row.is_some() {
            self.hint_job(&lease.job_id);
            if outcome == AttemptOutcome::Interrupted {
                self.hint_queued();
            }
        }
        Ok(row)
    }

    async fn finish_attempt(
        &self,
        tx: &mut sqlx::Transaction<'static, sqlx::Any>,
        lease: &Lease,
        outcome: AttemptOutcome,
        error: Option<&str>,
        now: i64,
    ) -> Result<(), StoreError> {
        sqlx::query(sql!("finish_attempt.sql"))
            .bind(&lease.job_id)
            .bind(lease.attempt)
            .bind(outcome.as_str())
            .bind(error)
            .bind(now)
            .execute(&mut **tx)
            .await?;
        Ok(())
    }
}
