-- A live stream's take holds a lease: the server coding it renews it while the stream is
-- open. A take whose lease has run out (its server died mid-stream) is closed by whichever
-- server sees it first. NULL: not live.
ALTER TABLE sequences ADD COLUMN live_until INTEGER;
CREATE INDEX sequences_live ON sequences (live_until) WHERE live_until IS NOT NULL;
