-- API tokens and the audit log (access control for teams).
--
-- A token's secret is never stored: `secret_hash` is the BLAKE3 of the secret the client
-- sends, and lookups go through it. `libraries` is a JSON array of library names the token
-- is limited to, or NULL for every library. A revoked token keeps its row (with
-- `revoked_at`), so the audit log can still name it and authentication stays on once any
-- token has existed.
CREATE TABLE tokens (
    id          TEXT PRIMARY KEY,
    name        TEXT NOT NULL UNIQUE,
    secret_hash BYTEA NOT NULL UNIQUE,
    scope       TEXT NOT NULL CHECK (scope IN ('read', 'write', 'admin')),
    libraries   TEXT,
    created_at  BIGINT NOT NULL,
    expires_at  BIGINT,
    revoked_at  BIGINT
);

-- Every write, delete, basis training and token change: who (the token's id and name, or
-- none), what (method, route, target), and how it ended (HTTP status).
CREATE TABLE audit_log (
    seq         BIGSERIAL PRIMARY KEY,
    at          BIGINT NOT NULL,
    token_id    TEXT,
    token_name  TEXT,
    action      TEXT NOT NULL,
    target      TEXT NOT NULL,
    status      INTEGER NOT NULL,
    detail      TEXT NOT NULL
);
CREATE INDEX audit_log_at ON audit_log (at);
