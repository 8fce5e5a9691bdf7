-- A job whose worker process dies under it (a lease that expires) is retried only
-- `max_lost_attempts` times: after that many lost attempts it fails as `poison`, so an input
-- that crashes the process cannot take the service down again after every restart.
-- `lost_attempts` counts the attempts lost so far (the claim that reclaims an expired lease
-- adds one; so does the reaper that gives up).
ALTER TABLE jobs ADD COLUMN lost_attempts INTEGER NOT NULL DEFAULT 0 CHECK (lost_attempts >= 0);
ALTER TABLE jobs ADD COLUMN max_lost_attempts INTEGER NOT NULL DEFAULT 2 CHECK (max_lost_attempts >= 1);
