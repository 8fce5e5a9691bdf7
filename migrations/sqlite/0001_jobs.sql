-- Job queue schema. Times are Unix milliseconds (UTC).

CREATE TABLE jobs (
    seq               INTEGER PRIMARY KEY AUTOINCREMENT, -- submission order, listing cursor
    id                TEXT    NOT NULL UNIQUE,           -- public UUID
    kind              TEXT    NOT NULL CHECK (kind IN ('text', 'vectorize')),
    spec              TEXT    NOT NULL,                  -- validated JobSpec as JSON
    priority          INTEGER NOT NULL DEFAULT 0,
    status            TEXT    NOT NULL DEFAULT 'queued'
                      CHECK (status IN ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
    idempotency_key   TEXT    UNIQUE,
    request_hash      TEXT,
    stage             TEXT,
    step              INTEGER NOT NULL DEFAULT 0,
    total             INTEGER NOT NULL DEFAULT 0,
    loss              REAL,
    attempts          INTEGER NOT NULL DEFAULT 0,
    max_attempts      INTEGER NOT NULL DEFAULT 3 CHECK (max_attempts >= 1),
    run_after         INTEGER NOT NULL,                  -- not claimable before (retry backoff)
    lease_owner       TEXT,
    lease_expires_at  INTEGER,
    heartbeat_at      INTEGER,
    cancel_requested  INTEGER NOT NULL DEFAULT 0 CHECK (cancel_requested IN (0, 1)),
    checkpoint        TEXT,                              -- executor state JSON, for resume
    checkpoint_at     INTEGER,
    error_code        TEXT,
    error_message     TEXT,
    created_at        INTEGER NOT NULL,
    started_at        INTEGER,
    finished_at       INTEGER,
    updated_at        INTEGER NOT NULL,
    CHECK ((status = 'running') = (lease_owner IS NOT NULL))
);

CREATE INDEX jobs_claim ON jobs (status, priority DESC, seq);
CREATE INDEX jobs_lease ON jobs (status, lease_expires_at);
CREATE INDEX jobs_finished ON jobs (finished_at);

CREATE TABLE attempts (
    job_id       TEXT    NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    attempt      INTEGER NOT NULL,
    worker       TEXT    NOT NULL,
    outcome      TEXT    NOT NULL DEFAULT 'running'
                 CHECK (outcome IN ('running', 'succeeded', 'failed', 'retry', 'cancelled',
                                    'lost', 'interrupted')),
    error        TEXT,
    started_at   INTEGER NOT NULL,
    finished_at  INTEGER,
    PRIMARY KEY (job_id, attempt)
);

CREATE TABLE snapshots (
    job_id      TEXT    NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    n           INTEGER NOT NULL,
    stage       TEXT    NOT NULL,
    step        INTEGER NOT NULL,
    svg         TEXT    NOT NULL,
    created_at  INTEGER NOT NULL,
    PRIMARY KEY (job_id, n)
);

CREATE TABLE results (
    job_id      TEXT    PRIMARY KEY REFERENCES jobs (id) ON DELETE CASCADE,
    svg         TEXT    NOT NULL,
    paths       INTEGER NOT NULL,
    detail      TEXT    NOT NULL,
    created_at  INTEGER NOT NULL
);
