-- An uploaded image is stored as its bytes (`image_bytes`, BYTEA), decoded from the request's
-- base64 once at submit; the worker reads the bytes back as they are. `image` (base64 TEXT) is
-- what older versions stored: it is no longer written, and an upload of a job queued across the
-- upgrade is read from it.
ALTER TABLE uploads ADD COLUMN image_bytes BYTEA;

ALTER TABLE uploads DROP CONSTRAINT IF EXISTS uploads_check;

ALTER TABLE uploads ADD CONSTRAINT uploads_has_content
    CHECK (image_bytes IS NOT NULL OR image IS NOT NULL OR svg IS NOT NULL);
