-- The results of a text job asked for more than one (`variations`): variation 1 is the row in
-- `results`, variations 2..N are here, numbered `n`, written in the same transaction.
CREATE TABLE result_variations (
    job_id      TEXT    NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    n           INTEGER NOT NULL CHECK (n >= 2),
    svg         TEXT    NOT NULL,
    paths       INTEGER NOT NULL,
    PRIMARY KEY (job_id, n)
);
