SELECT * FROM snapshots WHERE job_id = $1 AND n = $2
