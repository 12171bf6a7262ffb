-- Takes, their chunks and tags. A take is inserted in one transaction with its chunks.
CREATE TABLE sequences (
    id              TEXT PRIMARY KEY,
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
    bound_kind      TEXT NOT NULL,
    bound_mm        REAL NOT NULL,
    raw_bytes       INTEGER NOT NULL,
    stored_bytes    INTEGER NOT NULL,
    ratio           REAL NOT NULL,
    mean_mm         REAL NOT NULL,
    rms_mm          REAL NOT NULL,
    max_mm          REAL NOT NULL,
    kg_percent      REAL NOT NULL,
    header          BLOB NOT NULL,
    meta            TEXT NOT NULL,
    created_at      INTEGER NOT NULL
);
CREATE INDEX sequences_library ON sequences (library, created_at, id);
CREATE INDEX sequences_created ON sequences (created_at, id);
CREATE INDEX sequences_layout ON sequences (layout);

CREATE TABLE chunks (
    sequence_id TEXT NOT NULL REFERENCES sequences (id) ON DELETE CASCADE,
    idx         INTEGER NOT NULL,
    first_frame INTEGER NOT NULL,
    frames      INTEGER NOT NULL,
    crc32c      INTEGER NOT NULL,
    payload     BLOB NOT NULL,
    PRIMARY KEY (sequence_id, idx)
);

CREATE TABLE sequence_tags (
    sequence_id TEXT NOT NULL REFERENCES sequences (id) ON DELETE CASCADE,
    tag         TEXT NOT NULL,
    PRIMARY KEY (sequence_id, tag)
);
CREATE INDEX sequence_tags_tag ON sequence_tags (tag);
