-- Each take's error second by second (`motion::metrics::ErrorSeries` bytes: per second the
-- largest and mean error, 8 bytes), measured at ingest on the decode that was checked
-- against the bound; what the viewer charts. Takes stored before this, and live streams,
-- have none.
CREATE TABLE take_errors (
    sequence_id TEXT PRIMARY KEY REFERENCES sequences (id) ON DELETE CASCADE,
    series      BYTEA NOT NULL
);
