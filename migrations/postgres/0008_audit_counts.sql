-- Refused and failed requests are counted, not listed: one row per caller, status and minute
-- with how many there were (`count`), so that a flood of refusals adds a row a minute, not a
-- row (and its path) per request. Rows of requests that changed something keep count 1.
ALTER TABLE audit_log ADD COLUMN count BIGINT NOT NULL DEFAULT 1;

-- When a token was last presented (written at most once a minute per token).
ALTER TABLE tokens ADD COLUMN last_used_at BIGINT;
