-- Background jobs (training bases), seen by every server on the database. One server runs
-- a job under a lease it renews; when the lease runs out (its server died), another server
-- takes the job over and runs it again from the start. While a job runs, an identical
-- request (same dedup_key: the kind and the request) gets that job, not a second one.
CREATE TABLE jobs (
    id TEXT PRIMARY KEY,
    kind TEXT NOT NULL,
    dedup_key TEXT NOT NULL,
    request TEXT NOT NULL,          -- the request, JSON, to run it again on takeover
    libraries TEXT NOT NULL,        -- JSON array: who may see it
    state TEXT NOT NULL,            -- running, succeeded, failed
    progress DOUBLE PRECISION NOT NULL,
    message TEXT NOT NULL,
    result TEXT,                    -- JSON
    error TEXT,
    owner TEXT NOT NULL,            -- the server running it (a per-process id)
    lease_until BIGINT NOT NULL,   -- ms since the epoch
    attempts BIGINT NOT NULL,
    created_at BIGINT NOT NULL,
    finished_at BIGINT
);
CREATE UNIQUE INDEX jobs_running ON jobs (dedup_key) WHERE state = 'running';
CREATE INDEX jobs_lease ON jobs (lease_until) WHERE state = 'running';
CREATE INDEX jobs_created ON jobs (created_at);
