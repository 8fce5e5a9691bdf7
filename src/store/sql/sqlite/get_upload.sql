SELECT image, svg FROM uploads WHERE job_id = ?1
