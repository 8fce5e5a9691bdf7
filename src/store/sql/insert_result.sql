-- The primary key makes a second result for the same job an error: results are written once.
INSERT INTO results (job_id, svg, paths, detail, created_at) VALUES ($1, $2, $3, $4, $5)
