-- Earlier attempts still marked running belonged to a worker that lost its lease.
UPDATE attempts SET outcome = 'lost', error = 'lease expired', finished_at = $3
WHERE job_id = $1 AND attempt < $2 AND outcome = 'running'
