-- Takes, their chunks and tags. A take is inserted in one transaction with its chunks.
CREATE TABLE sequences (
    id              TEXT PRIMARY KEY,
    name            TEXT NOT NULL,
    library         TEXT NOT NULL DEFAULT '',
    fps             DOUBLE PRECISION NOT NULL,
    frames          BIGINT NOT NULL,
    points          BIGINT NOT NULL,
    duration_s      DOUBLE PRECISION NOT NULL,
    metres_per_unit DOUBLE PRECISION NOT NULL,
    layout          TEXT NOT NULL,
    source_format   TEXT NOT NULL,
    codec           TEXT NOT NULL,
    bound_kind      TEXT NOT NULL,
    bound_mm        DOUBLE PRECISION NOT NULL,
    raw_bytes       BIGINT NOT NULL,
    stored_bytes    BIGINT NOT NULL,
    ratio           DOUBLE PRECISION NOT NULL,
    mean_mm         DOUBLE PRECISION NOT NULL,
    rms_mm          DOUBLE PRECISION NOT NULL,
    max_mm          DOUBLE PRECISION NOT NULL,
    kg_percent      DOUBLE PRECISION NOT NULL,
    header          BYTEA NOT NULL,
    meta            TEXT NOT NULL,
    created_at      BIGINT NOT NULL
);
CREATE INDEX sequences_library ON sequences (library, created_at, id);
CREATE INDEX sequences_created ON sequences (created_at, id);
CREATE INDEX sequences_layout ON sequences (layout);

CREATE TABLE chunks (
    sequence_id TEXT NOT NULL REFERENCES sequences (id) ON DELETE CASCADE,
    idx         BIGINT NOT NULL,
    first_frame BIGINT NOT NULL,
    frames      BIGINT NOT NULL,
    crc32c      BIGINT NOT NULL,
    payload     BYTEA NOT NULL,
    PRIMARY KEY (sequence_id, idx)
);

CREATE TABLE sequence_tags (
    sequence_id TEXT NOT NULL REFERENCES sequences (id) ON DELETE CASCADE,
    tag         TEXT NOT NULL,
    PRIMARY KEY (sequence_id, tag)
);
CREATE INDEX sequence_tags_tag ON sequence_tags (tag);
