UPDATE attempts SET outcome = $3, error = $4, finished_at = $5
WHERE job_id = $1 AND attempt = $2 AND outcome = 'running'
