SELECT svg FROM result_variations WHERE job_id = $1 AND n = $2
