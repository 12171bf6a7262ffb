-- What a take keeps beside its points (issue 34): its analog channels, coded as a container
-- of their own (header here, chunks in analog_chunks, over the same frame ranges as the
-- take's point chunks), and the uploaded file's parameter section (a C3D parameter section
-- in Intel order, zstd-compressed). A take's raw_bytes and stored_bytes count both; the
-- sizes here let statistics split points from analog.
CREATE TABLE take_analog (
    sequence_id  TEXT PRIMARY KEY REFERENCES sequences (id) ON DELETE CASCADE,
    header       BLOB NOT NULL,
    raw_bytes    INTEGER NOT NULL,
    stored_bytes INTEGER NOT NULL
);

CREATE TABLE analog_chunks (
    sequence_id TEXT NOT NULL REFERENCES sequences (id) ON DELETE CASCADE,
    idx         INTEGER NOT NULL,
    first_frame INTEGER NOT NULL,
    frames      INTEGER NOT NULL,
    crc32c      INTEGER NOT NULL,
    payload     BLOB NOT NULL,
    PRIMARY KEY (sequence_id, idx)
);

CREATE TABLE take_parameters (
    sequence_id TEXT PRIMARY KEY REFERENCES sequences (id) ON DELETE CASCADE,
    format      TEXT NOT NULL,
    payload     BLOB NOT NULL
);
