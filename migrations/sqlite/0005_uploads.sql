-- Uploads (a vectorize job's image, the SVG a job starts from) live in their own table, not in
-- `jobs.spec`. SQLite rewrites a whole row on every UPDATE, so an upload kept in the job row was
-- written again with every progress tick, heartbeat and checkpoint (14–46× the body size per job).
-- The spec keeps an empty marker ("" for the image, "" for the SVG) so views still say an upload
-- was given; the worker reads the upload when it claims the job (`Store::upload`).
-- Retention: a job's upload is deleted when the job reaches a terminal status (the trigger
-- below); the bytes of active jobs' uploads are capped at submit (`Store::insert_job`).
CREATE TABLE uploads (
    job_id      TEXT    PRIMARY KEY REFERENCES jobs (id) ON DELETE CASCADE,
    tenant      TEXT,
    image       TEXT,                               -- base64, as the API received it
    svg         TEXT,
    bytes       INTEGER NOT NULL CHECK (bytes >= 0),
    created_at  INTEGER NOT NULL,
    CHECK (image IS NOT NULL OR svg IS NOT NULL)
);

CREATE INDEX uploads_tenant ON uploads (tenant);

INSERT INTO uploads (job_id, tenant, image, svg, bytes, created_at)
SELECT id, tenant,
       CASE WHEN json_type(spec, '$.image') = 'text' THEN json_extract(spec, '$.image') END,
       CASE WHEN json_type(spec, '$.svg') = 'text' THEN json_extract(spec, '$.svg') END,
       0, created_at
FROM jobs
WHERE status IN ('queued', 'running')
  AND (json_type(spec, '$.image') = 'text' OR json_type(spec, '$.svg') = 'text');

UPDATE uploads
SET bytes = COALESCE(length(CAST(image AS BLOB)), 0) + COALESCE(length(CAST(svg AS BLOB)), 0);

UPDATE jobs
SET spec = json_set(spec,
                    '$.image', CASE WHEN json_type(spec, '$.image') = 'text' THEN '' END,
                    '$.svg', CASE WHEN json_type(spec, '$.svg') = 'text' THEN '' END)
WHERE json_type(spec, '$.image') = 'text' OR json_type(spec, '$.svg') = 'text';

CREATE TRIGGER jobs_finish_drops_upload AFTER UPDATE OF status ON jobs
WHEN NEW.status IN ('succeeded', 'failed', 'cancelled')
BEGIN
    DELETE FROM uploads WHERE job_id = NEW.id;
END;
