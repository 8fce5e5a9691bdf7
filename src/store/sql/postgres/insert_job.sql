-- New job; an idempotency key already in use inserts nothing (caller then loads the existing job).
-- $11: when not NULL, insert only while fewer than $11 jobs are queued; the store runs this in a
-- transaction after taking the admission advisory lock (`admission_lock.sql`), so concurrent
-- submits near a full queue count one after another. NULL skips the count.
INSERT INTO jobs (id, kind, spec, priority, idempotency_key, request_hash, max_attempts,
                  max_lost_attempts, tenant, run_after, created_at, updated_at)
SELECT $1, $2, $3, $4, $5, $6, $7, $9, $10, $8, $8, $8
WHERE CASE WHEN $11::bigint IS NULL THEN true
           ELSE (SELECT COUNT(*) FROM jobs WHERE status = 'queued') < $11 END
ON CONFLICT (idempotency_key) DO NOTHING
RETURNING *
