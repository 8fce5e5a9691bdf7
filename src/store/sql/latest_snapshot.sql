SELECT * FROM snapshots WHERE job_id = $1 ORDER BY n DESC LIMIT 1
