-- Jobs belong to the tenant whose API key submitted them (NULL: the operator, or a server
-- without keys). Listings of one tenant read this index.
ALTER TABLE jobs ADD COLUMN tenant TEXT CHECK (tenant IS NULL OR length(tenant) BETWEEN 1 AND 64);
CREATE INDEX jobs_tenant ON jobs (tenant, seq);
