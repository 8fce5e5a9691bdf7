SELECT * FROM attempts WHERE job_id = $1 ORDER BY attempt
