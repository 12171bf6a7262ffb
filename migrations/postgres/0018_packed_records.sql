-- A take's record (its meta JSON) is kept packed: zstd with a dictionary of the words
-- records repeat (src/store/packed.rs), a seventh of the text. The JSON text moves aside
-- to meta_text; the store, when it opens, packs each row's into meta and drops meta_text,
-- in one transaction (src/store/migrate.rs): SQL alone cannot run zstd. A row written from
-- here on has meta only.
--
-- Stop every server of a store before the first one of this version opens it: a server of
-- an earlier version reads and writes meta as text. On Postgres the packing writes each
-- take's row anew; VACUUM FULL takes gives the old rows' room back to the disk.
ALTER TABLE takes RENAME COLUMN meta TO meta_text;
ALTER TABLE takes ADD COLUMN meta BYTEA;
