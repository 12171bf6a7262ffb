-- A take's motion features (issue 51): one descriptor per 1 s window, what search compares
-- (codec::features). Derived from the take as stored: the coding and body they were taken
-- from (codec, stored_bytes, frames, body_rev: the read path's stamp) are kept beside them,
-- so a take re-encoded, finished or given a corrected body has stale features until the
-- index job takes them again. `failed` says why a take gave none (its payload is empty).
CREATE TABLE take_features (
    take_id      TEXT PRIMARY KEY REFERENCES takes (id) ON DELETE CASCADE,
    codec        TEXT NOT NULL,
    stored_bytes BIGINT NOT NULL,
    frames       BIGINT NOT NULL,
    body_rev     BIGINT NOT NULL,
    payload      BLOB NOT NULL,
    failed       TEXT
);
