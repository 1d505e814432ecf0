-- A paired run (`collect --poses-from RUN`) takes the poses and rods of an earlier run,
-- so the finger meets the same deformations in another medium (land to water). NULL:
-- a run with poses of its own.
ALTER TABLE runs ADD COLUMN poses_from_run_id INTEGER REFERENCES runs (run_id) ON DELETE SET NULL;
