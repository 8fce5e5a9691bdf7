-- Extends the lease if this worker still holds it; returns the cancel flag. No row = lease lost.
UPDATE jobs SET lease_expires_at = $4::bigint + $5::bigint, heartbeat_at = $4, updated_at = $4
WHERE id = $1 AND lease_owner = $2 AND attempts = $3 AND status = 'running'
RETURNING cancel_requested
