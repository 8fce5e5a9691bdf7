-- Job queue schema for PostgreSQL: the same tables, constraints and triggers as the SQLite
-- migrations (`migrations/sqlite/0001`–`0005`) in their final form. Times are Unix milliseconds
-- (UTC); every integer is BIGINT so rows decode into the same Rust types on both backends.

CREATE TABLE jobs (
    seq               BIGSERIAL PRIMARY KEY,             -- submission order, listing cursor
    id                TEXT    NOT NULL UNIQUE,           -- public UUID
    kind              TEXT    NOT NULL CHECK (kind IN ('text', 'vectorize')),
    spec              TEXT    NOT NULL,                  -- validated JobSpec as JSON
    priority          BIGINT  NOT NULL DEFAULT 0,
    status            TEXT    NOT NULL DEFAULT 'queued'
                      CHECK (status IN ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
    idempotency_key   TEXT    UNIQUE,
    request_hash      TEXT,
    stage             TEXT,
    step              BIGINT  NOT NULL DEFAULT 0,
    total             BIGINT  NOT NULL DEFAULT 0,
    loss              DOUBLE PRECISION,
    attempts          BIGINT  NOT NULL DEFAULT 0,
    max_attempts      BIGINT  NOT NULL DEFAULT 3 CHECK (max_attempts >= 1),
    lost_attempts     BIGINT  NOT NULL DEFAULT 0 CHECK (lost_attempts >= 0),
    max_lost_attempts BIGINT  NOT NULL DEFAULT 2 CHECK (max_lost_attempts >= 1),
    run_after         BIGINT  NOT NULL,                  -- not claimable before (retry backoff)
    lease_owner       TEXT,
    lease_expires_at  BIGINT,
    heartbeat_at      BIGINT,
    cancel_requested  BIGINT  NOT NULL DEFAULT 0 CHECK (cancel_requested IN (0, 1)),
    checkpoint        TEXT,                              -- executor state JSON, for resume
    checkpoint_at     BIGINT,
    error_code        TEXT,
    error_message     TEXT,
    created_at        BIGINT  NOT NULL,
    started_at        BIGINT,
    finished_at       BIGINT,
    updated_at        BIGINT  NOT NULL,
    tenant            TEXT CHECK (tenant IS NULL OR length(tenant) BETWEEN 1 AND 64),
    CHECK ((status = 'running') = (lease_owner IS NOT NULL))
);

CREATE INDEX jobs_claim ON jobs (status, priority DESC, seq);
CREATE INDEX jobs_lease ON jobs (status, lease_expires_at);
CREATE INDEX jobs_finished ON jobs (finished_at);
CREATE INDEX jobs_tenant ON jobs (tenant, seq);

CREATE TABLE attempts (
    job_id       TEXT    NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    attempt      BIGINT  NOT NULL,
    worker       TEXT    NOT NULL,
    outcome      TEXT    NOT NULL DEFAULT 'running'
                 CHECK (outcome IN ('running', 'succeeded', 'failed', 'retry', 'cancelled',
                                    'lost', 'interrupted')),
    error        TEXT,
    started_at   BIGINT  NOT NULL,
    finished_at  BIGINT,
    PRIMARY KEY (job_id, attempt)
);

CREATE TABLE snapshots (
    job_id      TEXT    NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    n           BIGINT  NOT NULL,
    stage       TEXT    NOT NULL,
    step        BIGINT  NOT NULL,
    svg         TEXT    NOT NULL,
    created_at  BIGINT  NOT NULL,
    PRIMARY KEY (job_id, n)
);

CREATE TABLE results (
    job_id      TEXT    PRIMARY KEY REFERENCES jobs (id) ON DELETE CASCADE,
    svg         TEXT    NOT NULL,
    paths       BIGINT  NOT NULL,
    detail      TEXT    NOT NULL,
    created_at  BIGINT  NOT NULL
);

CREATE TABLE uploads (
    job_id      TEXT    PRIMARY KEY REFERENCES jobs (id) ON DELETE CASCADE,
    tenant      TEXT,
    image       TEXT,                               -- base64, as the API received it
    svg         TEXT,
    bytes       BIGINT  NOT NULL CHECK (bytes >= 0),
    created_at  BIGINT  NOT NULL,
    CHECK (image IS NOT NULL OR svg IS NOT NULL)
);

CREATE INDEX uploads_tenant ON uploads (tenant);

-- A claim (attempts + 1, status running) opens its `attempts` row and closes earlier attempts
-- still marked running as lost, inside the claiming UPDATE (as the SQLite trigger does).
CREATE FUNCTION jobs_claim_opens_attempt() RETURNS trigger LANGUAGE plpgsql AS $$
BEGIN
    UPDATE attempts SET outcome = 'lost', error = 'lease expired', finished_at = NEW.updated_at
    WHERE job_id = NEW.id AND attempt < NEW.attempts AND outcome = 'running';
    INSERT INTO attempts (job_id, attempt, worker, started_at)
    VALUES (NEW.id, NEW.attempts, NEW.lease_owner, NEW.updated_at);
    RETURN NULL;
END $$;

CREATE TRIGGER jobs_claim_opens_attempt AFTER UPDATE OF attempts ON jobs
FOR EACH ROW WHEN (NEW.attempts = OLD.attempts + 1 AND NEW.status = 'running')
EXECUTE FUNCTION jobs_claim_opens_attempt();

-- A job's upload is deleted when the job reaches a terminal status.
CREATE FUNCTION jobs_finish_drops_upload() RETURNS trigger LANGUAGE plpgsql AS $$
BEGIN
    DELETE FROM uploads WHERE job_id = NEW.id;
    RETURN NULL;
END $$;

CREATE TRIGGER jobs_finish_drops_upload AFTER UPDATE OF status ON jobs
FOR EACH ROW WHEN (NEW.status IN ('succeeded', 'failed', 'cancelled'))
EXECUTE FUNCTION jobs_finish_drops_upload();

-- No NOTIFY in triggers: a NOTIFY holds a database-wide lock through its transaction's commit
-- flush, which puts every committing transaction that sends one in single file. The store sends
-- its wake-up hints (`vf_queue`, `vf_job`) itself, after the write has committed
-- (`src/store/backend.rs`, `hints`).
