-- A claim (attempts + 1, status running, new lease owner) opens its `attempts` row, and closes
-- earlier attempts still marked running as lost, inside the claiming UPDATE itself. A claim is
-- then one autocommit statement instead of a BEGIN IMMEDIATE … COMMIT transaction of four round
-- trips holding the single writer connection that submits wait for.
CREATE TRIGGER jobs_claim_opens_attempt AFTER UPDATE OF attempts ON jobs
WHEN NEW.attempts = OLD.attempts + 1 AND NEW.status = 'running'
BEGIN
    UPDATE attempts SET outcome = 'lost', error = 'lease expired', finished_at = NEW.updated_at
    WHERE job_id = NEW.id AND attempt < NEW.attempts AND outcome = 'running';
    INSERT INTO attempts (job_id, attempt, worker, started_at)
    VALUES (NEW.id, NEW.attempts, NEW.lease_owner, NEW.updated_at);
END;
