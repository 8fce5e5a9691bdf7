UPDATE jobs SET checkpoint = $4, checkpoint_at = $5, updated_at = $5
WHERE id = $1 AND lease_owner = $2 AND attempts = $3 AND status = 'running'
