UPDATE jobs
SET status = 'cancelled', lease_owner = NULL, lease_expires_at = NULL, finished_at = $4,
    updated_at = $4
WHERE id = $1 AND lease_owner = $2 AND attempts = $3 AND status = 'running'
RETURNING *
