-- Queued and running jobs of one tenant (its `max_active_jobs` quota).
SELECT COUNT(*) FROM jobs WHERE tenant = $1 AND status IN ('queued', 'running')
