SELECT image_bytes, image AS image_base64, svg FROM uploads WHERE job_id = $1
