-- Shared bases (content addressed) and which takes were coded with which. A basis a take
-- references cannot be deleted: the take could no longer be decoded.
CREATE TABLE bases (
    id          TEXT PRIMARY KEY,
    kind        TEXT NOT NULL,
    layout      TEXT NOT NULL,
    points      BIGINT NOT NULL,
    dims        TEXT NOT NULL,
    payload     BYTEA NOT NULL,
    provenance  TEXT NOT NULL,
    created_at  BIGINT NOT NULL
);
CREATE INDEX bases_layout ON bases (layout, kind, created_at);

CREATE TABLE sequence_bases (
    sequence_id TEXT NOT NULL REFERENCES sequences (id) ON DELETE CASCADE,
    basis_id    TEXT NOT NULL REFERENCES bases (id) ON DELETE RESTRICT,
    PRIMARY KEY (sequence_id, basis_id)
);
CREATE INDEX sequence_bases_basis ON sequence_bases (basis_id);
