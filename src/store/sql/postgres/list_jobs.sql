-- Newest first; $2 is the cursor (the seq of the last job of the previous page); $4 a tenant
-- (NULL: every job). Uploads are not in the row (`uploads`); checkpoints stay in the database
-- (NULL here).
SELECT seq, id, kind, spec, priority, status, idempotency_key, request_hash, stage, step, total, loss, attempts,
       max_attempts, lost_attempts, max_lost_attempts, run_after, lease_owner, lease_expires_at,
       heartbeat_at, cancel_requested, NULL AS checkpoint, checkpoint_at, error_code,
       error_message, created_at, started_at, finished_at, updated_at, tenant
FROM jobs
WHERE ($1::text IS NULL OR status = $1) AND ($2::bigint IS NULL OR seq < $2) AND ($4::text IS NULL OR tenant = $4)
ORDER BY seq DESC
LIMIT $3
