-- Newest first; ?2 is the cursor (the seq of the last job of the previous page).
SELECT * FROM jobs
WHERE (?1 IS NULL OR status = ?1) AND (?2 IS NULL OR seq < ?2)
ORDER BY seq DESC
LIMIT ?3
