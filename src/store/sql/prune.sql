-- Retention: finished jobs (with their snapshots, results and attempts) older than $1 go.
DELETE FROM jobs
WHERE status IN ('succeeded', 'failed', 'cancelled') AND finished_at < $1
