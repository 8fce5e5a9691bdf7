-- Graceful shutdown: hand the job back to the queue; its checkpoint stays for the next worker.
UPDATE jobs
SET status = 'queued', lease_owner = NULL, lease_expires_at = NULL, run_after = $4,
    updated_at = $4
WHERE id = $1 AND lease_owner = $2 AND attempts = $3 AND status = 'running'
RETURNING *
