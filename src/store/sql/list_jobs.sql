-- Newest first; ?2 is the cursor (the seq of the last job of the previous page); ?4 a tenant
-- (NULL: every job). Uploads and checkpoints stay in the database: the image and SVG of the
-- spec become "" (so the view still says they were given) and the checkpoint NULL.
SELECT seq, id, kind,
       json_set(spec,
                '$.image', CASE WHEN json_type(spec, '$.image') = 'text' THEN '' END,
                '$.svg', CASE WHEN json_type(spec, '$.svg') = 'text' THEN '' END) AS spec,
       priority, status, idempotency_key, request_hash, stage, step, total, loss, attempts,
       max_attempts, lost_attempts, max_lost_attempts, run_after, lease_owner, lease_expires_at,
       heartbeat_at, cancel_requested, NULL AS checkpoint, checkpoint_at, error_code,
       error_message, created_at, started_at, finished_at, updated_at, tenant
FROM jobs
WHERE (?1 IS NULL OR status = ?1) AND (?2 IS NULL OR seq < ?2) AND (?4 IS NULL OR tenant = ?4)
ORDER BY seq DESC
LIMIT ?3
