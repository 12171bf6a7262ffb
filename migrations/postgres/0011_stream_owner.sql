-- A live take's stream may be sent to any server: the one coding it (stream_server, a
-- per-process id) is named with the address other servers forward its requests to
-- (stream_url). frames_received counts the frames its producer has had accepted, written
-- with every append, so that when the server dies the frames it took but never committed
-- (frames_received - frames) are known to the server that takes the stream over.
-- stream_state holds what a new coder needs to go on from the last committed chunk (frames
-- per chunk, the error sums so far), JSON, written with every chunk.
ALTER TABLE sequences ADD COLUMN stream_server TEXT;
ALTER TABLE sequences ADD COLUMN stream_url TEXT;
ALTER TABLE sequences ADD COLUMN frames_received BIGINT;
ALTER TABLE sequences ADD COLUMN stream_state TEXT;
