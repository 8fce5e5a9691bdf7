-- Atomic claim in one statement: the best queued job whose backoff has passed, or a running job
-- whose lease expired (its worker died) and that still has attempts left and has not been lost
-- `max_lost_attempts` times (reclaiming it counts one more lost attempt). SQLite takes the write
-- lock before evaluating the subquery, so two workers can never claim the same row.
-- ?1 worker id, ?2 now (ms), ?3 lease length (ms)
UPDATE jobs
SET status           = 'running',
    lease_owner      = ?1,
    lease_expires_at = ?2 + ?3,
    heartbeat_at     = ?2,
    attempts         = attempts + 1,
    lost_attempts    = lost_attempts + (status = 'running'),
    started_at       = COALESCE(started_at, ?2),
    updated_at       = ?2
WHERE seq = (
    SELECT seq FROM jobs
    WHERE cancel_requested = 0
      AND ((status = 'queued' AND run_after <= ?2)
           OR (status = 'running' AND lease_expires_at < ?2 AND attempts < max_attempts
               AND lost_attempts + 1 < max_lost_attempts))
    ORDER BY priority DESC, seq
    LIMIT 1)
RETURNING *
