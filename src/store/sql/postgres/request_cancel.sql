-- A queued job is cancelled at once; a running one is flagged and its worker stops at the next step.
-- In SET expressions PostgreSQL reads the old row, so every CASE sees the status before this update.
UPDATE jobs
SET status           = CASE WHEN status = 'queued' THEN 'cancelled' ELSE status END,
    cancel_requested = CASE WHEN status IN ('queued', 'running') THEN 1 ELSE cancel_requested END,
    finished_at      = CASE WHEN status = 'queued' THEN $2 ELSE finished_at END,
    updated_at       = $2
WHERE id = $1
RETURNING *
