-- Numbers continue across attempts; only the lease holder may add one.
INSERT INTO snapshots (job_id, n, stage, step, svg, created_at)
SELECT ?1, (SELECT COALESCE(MAX(n), 0) + 1 FROM snapshots WHERE job_id = ?1), ?4, ?5, ?6, ?7
WHERE EXISTS (SELECT 1 FROM jobs WHERE id = ?1 AND lease_owner = ?2 AND attempts = ?3
                                     AND status = 'running')
RETURNING n
