-- New job; an idempotency key already in use inserts nothing (caller then loads the existing job).
INSERT INTO jobs (id, kind, spec, priority, idempotency_key, request_hash, max_attempts,
                  max_lost_attempts, tenant, run_after, created_at, updated_at)
VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?9, ?10, ?8, ?8, ?8)
ON CONFLICT (idempotency_key) DO NOTHING
RETURNING *
