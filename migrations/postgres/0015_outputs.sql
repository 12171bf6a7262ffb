-- A take's model outputs (issue 49): the joint angles, forces, moments and powers a C3D's
-- POINT block carries beside its markers, kept apart from them exactly, with their kinds,
-- units and places among the file's points (codec::outputs: a description and one lossless
-- analog container). Read whole: they are small beside the markers.
CREATE TABLE take_outputs (
    take_id TEXT PRIMARY KEY REFERENCES takes (id) ON DELETE CASCADE,
    payload BYTEA NOT NULL
);
