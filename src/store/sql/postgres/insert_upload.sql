-- A new job's upload, only while the stored uploads stay within the quotas: $5 bytes more may
-- not take all uploads past $7 bytes, nor the tenant's ($2; NULL: the operator) past $8 (0: no
-- tenant cap). Runs in the submit's transaction after `admission_lock.sql`, so concurrent
-- submits cannot overshoot together.
INSERT INTO uploads (job_id, tenant, image_bytes, svg, bytes, created_at)
SELECT $1, $2, $3, $4, $5::bigint, $6
WHERE (SELECT COALESCE(SUM(bytes), 0) FROM uploads) + $5 <= $7
  AND ($8 = 0 OR (SELECT COALESCE(SUM(bytes), 0) FROM uploads
                  WHERE tenant IS NOT DISTINCT FROM $2) + $5 <= $8)
