-- Skeletons uploaded on their own (POST /v1/skeletons), not stored with a take: the format
-- of the file they came from, and for a glTF character that file itself (meshes, skin,
-- materials), which answers on its skeleton write back playing the take. NULL for the
-- skeletons of takes.
ALTER TABLE skeletons ADD COLUMN uploaded_as TEXT;
ALTER TABLE skeletons ADD COLUMN character_file BLOB;
