-- Skeletons (joint hierarchies), content addressed and stored once: every take of a BVH
-- skeleton references its own, and codecs that keep channel values decode with it. A
-- skeleton a take references cannot be deleted.
CREATE TABLE skeletons (
    id          TEXT PRIMARY KEY,
    layout      TEXT NOT NULL,
    joints      BIGINT NOT NULL,
    payload     BYTEA NOT NULL,
    created_at  BIGINT NOT NULL
);
CREATE INDEX skeletons_layout ON skeletons (layout, created_at);

ALTER TABLE sequences ADD COLUMN skeleton_id TEXT REFERENCES skeletons (id) ON DELETE RESTRICT;
CREATE INDEX sequences_skeleton ON sequences (skeleton_id) WHERE skeleton_id IS NOT NULL;
