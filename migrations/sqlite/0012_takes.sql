-- One word for one thing (docs/ARCHITECTURE.md, "Words"): a recording is a *take* in the
-- code, the API and the tables. Renamed in place: every row and key is kept, and foreign
-- keys follow their tables. The indexes are made again under their new names.
ALTER TABLE sequences RENAME TO takes;
ALTER TABLE sequence_tags RENAME TO take_tags;
ALTER TABLE sequence_bases RENAME TO take_bases;
ALTER TABLE chunks RENAME COLUMN sequence_id TO take_id;
ALTER TABLE take_tags RENAME COLUMN sequence_id TO take_id;
ALTER TABLE take_bases RENAME COLUMN sequence_id TO take_id;
ALTER TABLE take_errors RENAME COLUMN sequence_id TO take_id;
ALTER TABLE take_analog RENAME COLUMN sequence_id TO take_id;
ALTER TABLE analog_chunks RENAME COLUMN sequence_id TO take_id;
ALTER TABLE take_parameters RENAME COLUMN sequence_id TO take_id;

DROP INDEX sequences_library;
DROP INDEX sequences_created;
DROP INDEX sequences_layout;
DROP INDEX sequences_live;
DROP INDEX sequences_skeleton;
DROP INDEX sequence_tags_tag;
DROP INDEX sequence_bases_basis;
CREATE INDEX takes_library ON takes (library, created_at, id);
CREATE INDEX takes_created ON takes (created_at, id);
CREATE INDEX takes_layout ON takes (layout);
CREATE INDEX takes_live ON takes (live_until) WHERE live_until IS NOT NULL;
CREATE INDEX takes_skeleton ON takes (skeleton_id) WHERE skeleton_id IS NOT NULL;
CREATE INDEX take_tags_tag ON take_tags (tag);
CREATE INDEX take_bases_basis ON take_bases (basis_id);
