-- A take's body (its axes and roles, in meta) can change without its coding changing: it
-- is derived once for a take stored before bodies were kept, and a user corrects it by
-- PATCH. body_rev counts those changes, so that a decoder cached on any server (which
-- holds the body's stance) sees by its stamp that it must be built again.
ALTER TABLE takes ADD COLUMN body_rev BIGINT NOT NULL DEFAULT 0;
