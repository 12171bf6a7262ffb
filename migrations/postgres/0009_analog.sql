-- What a take keeps beside its points (issue 34): its analog channels, coded as a container
-- of their own (header here, chunks in analog_chunks, over the same frame ranges as the
-- take's point chunks), and the uploaded file's parameter section (a C3D parameter section
-- in Intel order, zstd-compressed). A take's raw_bytes and stored_bytes count both; the
-- sizes here let statistics split points from analog.
CREATE TABLE take_analog (
    sequence_id  TEXT PRIMARY KEY REFERENCES sequences (id) ON DELETE CASCADE,
    header       BYTEA NOT NULL,
    raw_bytes    BIGINT NOT NULL,
    stored_bytes BIGINT NOT NULL
);

CREATE TABLE analog_chunks (
    sequence_id TEXT NOT NULL REFERENCES sequences (id) ON DELETE CASCADE,
    idx         BIGINT NOT NULL,
    first_frame BIGINT NOT NULL,
    frames      BIGINT NOT NULL,
    crc32c      BIGINT NOT NULL,
    payload     BYTEA NOT NULL,
    PRIMARY KEY (sequence_id, idx)
);

CREATE TABLE take_parameters (
    sequence_id TEXT PRIMARY KEY REFERENCES sequences (id) ON DELETE CASCADE,
    format      TEXT NOT NULL,
    payload     BYTEA NOT NULL
);
