-- Running jobs whose lease expired and that cannot be reclaimed: cancelled if a cancel was
-- requested; failed as `poison` once lost `max_lost_attempts` times (the input may be what kills
-- the worker); otherwise failed after using up their attempts.
UPDATE jobs
SET status           = CASE WHEN cancel_requested = 1 THEN 'cancelled' ELSE 'failed' END,
    error_code       = CASE WHEN cancel_requested = 1 THEN NULL
                            WHEN lost_attempts + 1 >= max_lost_attempts THEN 'poison'
                            ELSE 'lease_expired' END,
    error_message    = CASE WHEN cancel_requested = 1 THEN NULL
                            WHEN lost_attempts + 1 >= max_lost_attempts
                            THEN 'the worker running this job stopped responding ' || (lost_attempts + 1)
                                 || ' times (the job may crash the process that runs it); not retried'
                            ELSE 'the worker running this job stopped responding (' || attempts
                                 || ' attempts)' END,
    lost_attempts    = CASE WHEN cancel_requested = 1 THEN lost_attempts ELSE lost_attempts + 1 END,
    lease_owner      = NULL,
    lease_expires_at = NULL,
    finished_at      = $1,
    updated_at       = $1
WHERE status = 'running' AND lease_expires_at < $1
  AND (cancel_requested = 1 OR attempts >= max_attempts OR lost_attempts + 1 >= max_lost_attempts)
RETURNING *
