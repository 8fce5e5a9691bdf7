-- An uploaded image is stored as its bytes (`image_bytes`, BLOB), decoded from the request's
-- base64 once at submit; the worker reads the bytes back as they are. `image` (base64 TEXT) is
-- what older versions stored: it is no longer written, and an upload of a job queued across the
-- upgrade is read from it. SQLite cannot change a table's CHECK, so the table is rebuilt (the
-- trigger that drops a finished job's upload names it, so it is dropped and made again).
DROP TRIGGER jobs_finish_drops_upload;

CREATE TABLE uploads_v2 (
    job_id      TEXT    PRIMARY KEY REFERENCES jobs (id) ON DELETE CASCADE,
    tenant      TEXT,
    image_bytes BLOB,                               -- the image file (PNG or JPEG)
    image       TEXT,                               -- base64 (older versions only)
    svg         TEXT,
    bytes       INTEGER NOT NULL CHECK (bytes >= 0),
    created_at  INTEGER NOT NULL,
    CHECK (image_bytes IS NOT NULL OR image IS NOT NULL OR svg IS NOT NULL)
);

INSERT INTO uploads_v2 (job_id, tenant, image, svg, bytes, created_at)
SELECT job_id, tenant, image, svg, bytes, created_at FROM uploads;

DROP TABLE uploads;

ALTER TABLE uploads_v2 RENAME TO uploads;

CREATE INDEX uploads_tenant ON uploads (tenant);

CREATE TRIGGER jobs_finish_drops_upload AFTER UPDATE OF status ON jobs
WHEN NEW.status IN ('succeeded', 'failed', 'cancelled')
BEGIN
    DELETE FROM uploads WHERE job_id = NEW.id;
END;
