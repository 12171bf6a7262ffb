-- Chunks kept by an integer key (issue 53, part 3). A chunk row was keyed by its take's
-- 36-character id and its index, in the row and again in the primary key's index.
--
-- Each take now has an integer key (`takes.key`, from the sequence take_keys), and a
-- chunk's row is keyed by `take key × 2^32 + chunk index`: an eight-byte index entry. Chunk
-- indices stay under 2^32 (a take has at most 20 million frames, `limits.rs`). The store
-- deletes a take's chunks with it (no foreign key can follow a computed key).
CREATE SEQUENCE take_keys;
ALTER TABLE takes ADD COLUMN key BIGINT;
UPDATE takes SET key = k.key FROM (
    SELECT id, row_number() OVER (ORDER BY created_at, id) AS key FROM takes
) k WHERE takes.id = k.id;
SELECT setval('take_keys', COALESCE((SELECT MAX(key) FROM takes), 0) + 1, false);
ALTER TABLE takes ALTER COLUMN key SET DEFAULT nextval('take_keys');
ALTER TABLE takes ALTER COLUMN key SET NOT NULL;
ALTER SEQUENCE take_keys OWNED BY takes.key;
CREATE UNIQUE INDEX takes_key ON takes (key);

CREATE TABLE chunks_by_key (
    key         BIGINT PRIMARY KEY,  -- take key × 2^32 + chunk index
    first_frame BIGINT NOT NULL,
    frames      BIGINT NOT NULL,
    crc32c      BIGINT NOT NULL,
    payload     BYTEA NOT NULL
);
INSERT INTO chunks_by_key (key, first_frame, frames, crc32c, payload)
    SELECT t.key * 4294967296 + c.idx, c.first_frame, c.frames, c.crc32c, c.payload
    FROM chunks c JOIN takes t ON t.id = c.take_id ORDER BY t.key, c.idx;
DROP TABLE chunks;
ALTER TABLE chunks_by_key RENAME TO chunks;
ALTER INDEX chunks_by_key_pkey RENAME TO chunks_pkey;

CREATE TABLE analog_chunks_by_key (
    key         BIGINT PRIMARY KEY,  -- take key × 2^32 + chunk index
    first_frame BIGINT NOT NULL,
    frames      BIGINT NOT NULL,
    crc32c      BIGINT NOT NULL,
    payload     BYTEA NOT NULL
);
INSERT INTO analog_chunks_by_key (key, first_frame, frames, crc32c, payload)
    SELECT t.key * 4294967296 + c.idx, c.first_frame, c.frames, c.crc32c, c.payload
    FROM analog_chunks c JOIN takes t ON t.id = c.take_id ORDER BY t.key, c.idx;
DROP TABLE analog_chunks;
ALTER TABLE analog_chunks_by_key RENAME TO analog_chunks;
ALTER INDEX analog_chunks_by_key_pkey RENAME TO analog_chunks_pkey;
