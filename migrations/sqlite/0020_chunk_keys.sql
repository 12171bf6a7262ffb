-- Chunks kept by an integer key (issue 53, part 3). A chunk row was keyed by its take's
-- 36-character id and its index, twice over (in the row and in the primary key's index),
-- and inserted at the id's random place in that index, which leaves pages part empty.
--
-- Each take now has an integer key (`takes.key`: a new take gets the largest plus one, by
-- the trigger below), and a chunk's row is keyed by `take key × 2^32 + chunk index`, its
-- rowid: one B-tree, no second index, and a new take's chunks go in at its end, filling
-- each page. Chunk indices stay under 2^32 (a take has at most 20 million frames,
-- `limits.rs`); keys under 2^31 takes. The store deletes a take's chunks with it
-- (no foreign key can follow a computed key).
ALTER TABLE takes ADD COLUMN key INTEGER;
UPDATE takes SET key = rowid;
CREATE UNIQUE INDEX takes_key ON takes (key);
CREATE TRIGGER takes_key AFTER INSERT ON takes FOR EACH ROW WHEN NEW.key IS NULL
BEGIN
    UPDATE takes SET key = COALESCE((SELECT MAX(key) FROM takes), 0) + 1
    WHERE rowid = NEW.rowid;
END;

-- Copied take after take, in key order (CROSS JOIN keeps takes as the outer loop, walked
-- by takes_key): the new table fills at its end, and only one take's chunks are sorted at
-- a time.
CREATE TABLE chunks_by_key (
    key         INTEGER PRIMARY KEY,  -- take key × 2^32 + chunk index
    first_frame INTEGER NOT NULL,
    frames      INTEGER NOT NULL,
    crc32c      INTEGER NOT NULL,
    payload     BLOB NOT NULL
);
INSERT INTO chunks_by_key (key, first_frame, frames, crc32c, payload)
    SELECT t.key * 4294967296 + c.idx, c.first_frame, c.frames, c.crc32c, c.payload
    FROM takes t CROSS JOIN chunks c ON c.take_id = t.id ORDER BY t.key, c.idx;
DROP TABLE chunks;
ALTER TABLE chunks_by_key RENAME TO chunks;

CREATE TABLE analog_chunks_by_key (
    key         INTEGER PRIMARY KEY,  -- take key × 2^32 + chunk index
    first_frame INTEGER NOT NULL,
    frames      INTEGER NOT NULL,
    crc32c      INTEGER NOT NULL,
    payload     BLOB NOT NULL
);
INSERT INTO analog_chunks_by_key (key, first_frame, frames, crc32c, payload)
    SELECT t.key * 4294967296 + c.idx, c.first_frame, c.frames, c.crc32c, c.payload
    FROM takes t CROSS JOIN analog_chunks c ON c.take_id = t.id ORDER BY t.key, c.idx;
DROP TABLE analog_chunks;
ALTER TABLE analog_chunks_by_key RENAME TO analog_chunks;
