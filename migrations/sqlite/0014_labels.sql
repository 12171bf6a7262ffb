-- A take's labels (crate::labels): key → value. `value` is the canonical text that filters
-- compare (`label.style=0`); `number` says whether it was given as a number, so that it
-- reads back as one.
CREATE TABLE take_labels (
    take_id TEXT NOT NULL REFERENCES takes (id) ON DELETE CASCADE,
    key     TEXT NOT NULL,
    value   TEXT NOT NULL,
    number  INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (take_id, key)
);
CREATE INDEX take_labels_key_value ON take_labels (key, value);
