-- The finger's frames at a grasp trial's moments (first contact, confirmation, lift,
-- end; those that happened), as PNG thumbnails at most 160 px wide, written in the
-- trial's transaction with its trace. What the report's trial viewer shows beside the
-- trace; a trial stored before this migration has none.
CREATE TABLE grasp_trial_frames (
    trial_id INTEGER NOT NULL REFERENCES grasp_trials (trial_id) ON DELETE CASCADE,
    moment   TEXT    NOT NULL CHECK (moment IN ('contact', 'confirmed', 'lifted', 'end')),
    t_s      REAL    NOT NULL,  -- exposure, s after the trial's start
    png      BLOB    NOT NULL CHECK (length(png) > 8),
    PRIMARY KEY (trial_id, moment)
);
