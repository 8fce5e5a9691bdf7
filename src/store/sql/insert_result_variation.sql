-- Variation n (2..N) of a job's result; run in one transaction with insert_result.sql.
INSERT INTO result_variations (job_id, n, svg, paths) VALUES ($1, $2, $3, $4)
