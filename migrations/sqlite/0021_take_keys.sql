-- Everything of a take is kept by its integer key (issue 53), as its chunks are since
-- 0020: each table of a take's (tags, bases, analog header, parameters, labels, outputs,
-- features) names it by `take_key`, not by its 36-character id, and a take's key is its
-- row's rowid, so that it needs no index of its own. One row a take is keyed by the
-- rowid; the rest keep their primary keys with `take_key` first.
--
-- SQLite cannot change a table's key in place: `takes` is made anew, and with it every
-- table that refers to it (renaming `takes` first points their foreign keys at the old
-- one, which is dropped once none does). Rows, keys and ids are kept as they were.
ALTER TABLE takes RENAME TO takes_old;
CREATE TABLE takes (
    key             INTEGER PRIMARY KEY,
    id              TEXT NOT NULL UNIQUE,
    name            TEXT NOT NULL,
    library         TEXT NOT NULL DEFAULT '',
    fps             REAL NOT NULL,
    frames          INTEGER NOT NULL,
    points          INTEGER NOT NULL,
    duration_s      REAL NOT NULL,
    metres_per_unit REAL NOT NULL,
    layout          TEXT NOT NULL,
    source_format   TEXT NOT NULL,
    codec           TEXT NOT NULL,
    raw_bytes       INTEGER NOT NULL,
    stored_bytes    INTEGER NOT NULL,
    ratio           REAL NOT NULL,
    mean_mm         REAL NOT NULL,
    rms_mm          REAL NOT NULL,
    max_mm          REAL NOT NULL,
    kg_percent      REAL NOT NULL,
    max_bound_mm    REAL NOT NULL DEFAULT 0,
    mean_bound_mm   REAL,
    created_at      INTEGER NOT NULL,
    live_until      INTEGER,
    skeleton_id     TEXT REFERENCES skeletons (id) ON DELETE RESTRICT,
    stream_server   TEXT,
    stream_url      TEXT,
    frames_received INTEGER,
    stream_state    TEXT,
    body_rev        INTEGER NOT NULL DEFAULT 0,
    header          BLOB NOT NULL,
    meta            BLOB NOT NULL,
    errors          BLOB
);
-- A record 0018 could not pack was kept as it was; one that is missing reads as empty,
-- which does not unpack: its take reads as corrupt, as before.
INSERT INTO takes (key, id, name, library, fps, frames, points, duration_s, metres_per_unit,
    layout, source_format, codec, raw_bytes, stored_bytes, ratio, mean_mm, rms_mm, max_mm,
    kg_percent, max_bound_mm, mean_bound_mm, created_at, live_until, skeleton_id,
    stream_server, stream_url, frames_received, stream_state, body_rev, header, meta, errors)
SELECT key, id, name, library, fps, frames, points, duration_s, metres_per_unit,
    layout, source_format, codec, raw_bytes, stored_bytes, ratio, mean_mm, rms_mm, max_mm,
    kg_percent, max_bound_mm, mean_bound_mm, created_at, live_until, skeleton_id,
    stream_server, stream_url, frames_received, stream_state, body_rev, header,
    COALESCE(meta, x''), errors
FROM takes_old ORDER BY key;

CREATE TABLE take_tags_new (
    take_key INTEGER NOT NULL REFERENCES takes (key) ON DELETE CASCADE,
    tag      TEXT NOT NULL,
    PRIMARY KEY (take_key, tag)
);
INSERT INTO take_tags_new (take_key, tag)
    SELECT t.key, c.tag FROM take_tags c JOIN takes_old t ON t.id = c.take_id;
DROP TABLE take_tags;
ALTER TABLE take_tags_new RENAME TO take_tags;
CREATE INDEX take_tags_tag ON take_tags (tag);

CREATE TABLE take_bases_new (
    take_key INTEGER NOT NULL REFERENCES takes (key) ON DELETE CASCADE,
    basis_id TEXT NOT NULL REFERENCES bases (id) ON DELETE RESTRICT,
    PRIMARY KEY (take_key, basis_id)
);
INSERT INTO take_bases_new (take_key, basis_id)
    SELECT t.key, c.basis_id FROM take_bases c JOIN takes_old t ON t.id = c.take_id;
DROP TABLE take_bases;
ALTER TABLE take_bases_new RENAME TO take_bases;
CREATE INDEX take_bases_basis ON take_bases (basis_id);

CREATE TABLE take_analog_new (
    take_key     INTEGER PRIMARY KEY REFERENCES takes (key) ON DELETE CASCADE,
    header       BLOB NOT NULL,
    raw_bytes    INTEGER NOT NULL,
    stored_bytes INTEGER NOT NULL
);
INSERT INTO take_analog_new (take_key, header, raw_bytes, stored_bytes)
    SELECT t.key, c.header, c.raw_bytes, c.stored_bytes
    FROM take_analog c JOIN takes_old t ON t.id = c.take_id;
DROP TABLE take_analog;
ALTER TABLE take_analog_new RENAME TO take_analog;

CREATE TABLE take_parameters_new (
    take_key INTEGER PRIMARY KEY REFERENCES takes (key) ON DELETE CASCADE,
    format   TEXT NOT NULL,
    payload  BLOB NOT NULL
);
INSERT INTO take_parameters_new (take_key, format, payload)
    SELECT t.key, c.format, c.payload FROM take_parameters c JOIN takes_old t ON t.id = c.take_id;
DROP TABLE take_parameters;
ALTER TABLE take_parameters_new RENAME TO take_parameters;

CREATE TABLE take_labels_new (
    take_key INTEGER NOT NULL REFERENCES takes (key) ON DELETE CASCADE,
    key      TEXT NOT NULL,
    value    TEXT NOT NULL,
    number   INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (take_key, key)
);
INSERT INTO take_labels_new (take_key, key, value, number)
    SELECT t.key, c.key, c.value, c.number FROM take_labels c JOIN takes_old t ON t.id = c.take_id;
DROP TABLE take_labels;
ALTER TABLE take_labels_new RENAME TO take_labels;
CREATE INDEX take_labels_key_value ON take_labels (key, value);

CREATE TABLE take_outputs_new (
    take_key INTEGER PRIMARY KEY REFERENCES takes (key) ON DELETE CASCADE,
    payload  BLOB NOT NULL
);
INSERT INTO take_outputs_new (take_key, payload)
    SELECT t.key, c.payload FROM take_outputs c JOIN takes_old t ON t.id = c.take_id;
DROP TABLE take_outputs;
ALTER TABLE take_outputs_new RENAME TO take_outputs;

CREATE TABLE take_features_new (
    take_key     INTEGER PRIMARY KEY REFERENCES takes (key) ON DELETE CASCADE,
    codec        TEXT NOT NULL,
    stored_bytes BIGINT NOT NULL,
    frames       BIGINT NOT NULL,
    body_rev     BIGINT NOT NULL,
    payload      BLOB NOT NULL,
    failed       TEXT
);
INSERT INTO take_features_new (take_key, codec, stored_bytes, frames, body_rev, payload, failed)
    SELECT t.key, c.codec, c.stored_bytes, c.frames, c.body_rev, c.payload, c.failed
    FROM take_features c JOIN takes_old t ON t.id = c.take_id;
DROP TABLE take_features;
ALTER TABLE take_features_new RENAME TO take_features;

-- Nothing refers to the old table now (its trigger and indexes go with it).
DROP TABLE takes_old;
-- A page of the library ends with its last take's key, not its id (the cursor): these two
-- end with the rowid, which is the key.
CREATE INDEX takes_library ON takes (library, created_at);
CREATE INDEX takes_created ON takes (created_at);
CREATE INDEX takes_layout ON takes (layout);
CREATE INDEX takes_live ON takes (live_until) WHERE live_until IS NOT NULL;
CREATE INDEX takes_skeleton ON takes (skeleton_id) WHERE skeleton_id IS NOT NULL;
