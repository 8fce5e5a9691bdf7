-- Serialises the inserts that count something (a queue near full, upload quotas) until the end
-- of the transaction: SQLite gets the same from its single writer.
SELECT pg_advisory_xact_lock(7374001)
