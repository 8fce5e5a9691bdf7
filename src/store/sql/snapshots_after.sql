SELECT * FROM snapshots WHERE job_id = $1 AND n > $2 ORDER BY n LIMIT $3
