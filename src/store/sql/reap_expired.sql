-- Running jobs whose lease expired and that cannot be reclaimed: cancelled if a cancel was
-- requested, otherwise failed after using up their attempts.
UPDATE jobs
SET status           = CASE WHEN cancel_requested = 1 THEN 'cancelled' ELSE 'failed' END,
    error_code       = CASE WHEN cancel_requested = 1 THEN NULL ELSE 'lease_expired' END,
    error_message    = CASE WHEN cancel_requested = 1 THEN NULL
                            ELSE 'the worker running this job stopped responding (' || attempts
                                 || ' attempts)' END,
    lease_owner      = NULL,
    lease_expires_at = NULL,
    finished_at      = ?1,
    updated_at       = ?1
WHERE status = 'running' AND lease_expires_at < ?1
  AND (cancel_requested = 1 OR attempts >= max_attempts)
RETURNING *
