UPDATE jobs SET stage = $4, step = $5, total = $6, loss = $7, updated_at = $8
WHERE id = $1 AND lease_owner = $2 AND attempts = $3 AND status = 'running'
