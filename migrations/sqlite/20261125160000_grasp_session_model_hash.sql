-- A grasp session records the sha256 of the model artifact it ran, so a table can be
-- traced to the exact weights and a resume refuses a model replaced under the same
-- name. NULL: a session started before this migration.
ALTER TABLE grasp_sessions ADD COLUMN model_sha256 TEXT;
