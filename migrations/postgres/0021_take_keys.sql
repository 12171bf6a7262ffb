-- Everything of a take is kept by its integer key (issue 53), as its chunks are since
-- 0020: each table of a take's (tags, bases, analog header, parameters, labels, outputs,
-- features) names it by `take_key`, not by its 36-character id, in its rows and in its
-- primary key's index, which now leads with it. Rows are kept; the column is added,
-- filled from the take's key, and the id's column (and the keys on it) dropped. Each
-- table's rows are written anew: VACUUM FULL gives the old rows' room back to the disk.

ALTER TABLE take_tags ADD COLUMN take_key BIGINT;
UPDATE take_tags c SET take_key = t.key FROM takes t WHERE t.id = c.take_id;
ALTER TABLE take_tags ALTER COLUMN take_key SET NOT NULL;
ALTER TABLE take_tags DROP COLUMN take_id;
ALTER TABLE take_tags ADD CONSTRAINT take_tags_pkey PRIMARY KEY (take_key, tag);
ALTER TABLE take_tags ADD CONSTRAINT take_tags_take_key_fkey
    FOREIGN KEY (take_key) REFERENCES takes (key) ON DELETE CASCADE;

ALTER TABLE take_bases ADD COLUMN take_key BIGINT;
UPDATE take_bases c SET take_key = t.key FROM takes t WHERE t.id = c.take_id;
ALTER TABLE take_bases ALTER COLUMN take_key SET NOT NULL;
ALTER TABLE take_bases DROP COLUMN take_id;
ALTER TABLE take_bases ADD CONSTRAINT take_bases_pkey PRIMARY KEY (take_key, basis_id);
ALTER TABLE take_bases ADD CONSTRAINT take_bases_take_key_fkey
    FOREIGN KEY (take_key) REFERENCES takes (key) ON DELETE CASCADE;

ALTER TABLE take_analog ADD COLUMN take_key BIGINT;
UPDATE take_analog c SET take_key = t.key FROM takes t WHERE t.id = c.take_id;
ALTER TABLE take_analog ALTER COLUMN take_key SET NOT NULL;
ALTER TABLE take_analog DROP COLUMN take_id;
ALTER TABLE take_analog ADD CONSTRAINT take_analog_pkey PRIMARY KEY (take_key);
ALTER TABLE take_analog ADD CONSTRAINT take_analog_take_key_fkey
    FOREIGN KEY (take_key) REFERENCES takes (key) ON DELETE CASCADE;

ALTER TABLE take_parameters ADD COLUMN take_key BIGINT;
UPDATE take_parameters c SET take_key = t.key FROM takes t WHERE t.id = c.take_id;
ALTER TABLE take_parameters ALTER COLUMN take_key SET NOT NULL;
ALTER TABLE take_parameters DROP COLUMN take_id;
ALTER TABLE take_parameters ADD CONSTRAINT take_parameters_pkey PRIMARY KEY (take_key);
ALTER TABLE take_parameters ADD CONSTRAINT take_parameters_take_key_fkey
    FOREIGN KEY (take_key) REFERENCES takes (key) ON DELETE CASCADE;

ALTER TABLE take_labels ADD COLUMN take_key BIGINT;
UPDATE take_labels c SET take_key = t.key FROM takes t WHERE t.id = c.take_id;
ALTER TABLE take_labels ALTER COLUMN take_key SET NOT NULL;
ALTER TABLE take_labels DROP COLUMN take_id;
ALTER TABLE take_labels ADD CONSTRAINT take_labels_pkey PRIMARY KEY (take_key, key);
ALTER TABLE take_labels ADD CONSTRAINT take_labels_take_key_fkey
    FOREIGN KEY (take_key) REFERENCES takes (key) ON DELETE CASCADE;

ALTER TABLE take_outputs ADD COLUMN take_key BIGINT;
UPDATE take_outputs c SET take_key = t.key FROM takes t WHERE t.id = c.take_id;
ALTER TABLE take_outputs ALTER COLUMN take_key SET NOT NULL;
ALTER TABLE take_outputs DROP COLUMN take_id;
ALTER TABLE take_outputs ADD CONSTRAINT take_outputs_pkey PRIMARY KEY (take_key);
ALTER TABLE take_outputs ADD CONSTRAINT take_outputs_take_key_fkey
    FOREIGN KEY (take_key) REFERENCES takes (key) ON DELETE CASCADE;

ALTER TABLE take_features ADD COLUMN take_key BIGINT;
UPDATE take_features c SET take_key = t.key FROM takes t WHERE t.id = c.take_id;
ALTER TABLE take_features ALTER COLUMN take_key SET NOT NULL;
ALTER TABLE take_features DROP COLUMN take_id;
ALTER TABLE take_features ADD CONSTRAINT take_features_pkey PRIMARY KEY (take_key);
ALTER TABLE take_features ADD CONSTRAINT take_features_take_key_fkey
    FOREIGN KEY (take_key) REFERENCES takes (key) ON DELETE CASCADE;

-- A page of the library ends with its last take's key, not its id (the cursor).
DROP INDEX takes_library;
DROP INDEX takes_created;
CREATE INDEX takes_library ON takes (library, created_at, key);
CREATE INDEX takes_created ON takes (created_at, key);
