-- $4 = retry time (ms): re-queue with backoff; NULL: fail for good.
UPDATE jobs
SET status           = CASE WHEN $4::bigint IS NULL THEN 'failed' ELSE 'queued' END,
    run_after        = COALESCE($4, run_after),
    error_code       = $5,
    error_message    = $6,
    lease_owner      = NULL,
    lease_expires_at = NULL,
    finished_at      = CASE WHEN $4::bigint IS NULL THEN $7::bigint ELSE NULL END,
    updated_at       = $7::bigint
WHERE id = $1 AND lease_owner = $2 AND attempts = $3 AND status = 'running'
RETURNING *
