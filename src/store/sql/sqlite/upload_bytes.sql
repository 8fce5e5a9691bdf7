-- Bytes of stored uploads: all (?1 = 0) or one tenant's (?1 = 1, ?2 the tenant; NULL the operator).
SELECT COALESCE(SUM(bytes), 0) FROM uploads WHERE ?1 = 0 OR tenant IS ?2
