-- A take's error over time (`motion::metrics::ErrorSeries` bytes, 8 a second) moves into its
-- row: one value per take, read with nothing else, did not need a table of its own, whose
-- key repeated the take's id and whose index repeated it again (about 200 bytes a take,
-- and on Postgres a table's own pages and maps). Last in the row, so that reading the
-- columns before it never reads it.
ALTER TABLE takes ADD COLUMN errors BYTEA;
UPDATE takes SET errors = (SELECT series FROM take_errors WHERE take_errors.take_id = takes.id);
DROP TABLE take_errors;
