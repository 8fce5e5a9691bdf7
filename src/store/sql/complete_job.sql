-- Only the current lease holder can complete; run in one transaction with insert_result.sql.
UPDATE jobs
SET status = 'succeeded', lease_owner = NULL, lease_expires_at = NULL, checkpoint = NULL,
    error_code = NULL, error_message = NULL, finished_at = $4, updated_at = $4
WHERE id = $1 AND lease_owner = $2 AND attempts = $3 AND status = 'running'
