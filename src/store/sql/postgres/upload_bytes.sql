-- Bytes of stored uploads: all ($1 = 0) or one tenant's ($1 = 1, $2 the tenant; NULL the operator).
SELECT COALESCE(SUM(bytes), 0)::bigint FROM uploads WHERE $1 = 0 OR tenant IS NOT DISTINCT FROM $2
