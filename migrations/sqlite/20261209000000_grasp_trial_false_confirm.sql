-- A closed loop that confirms its force on an estimate the fingers never felt (the
-- true force stayed at the touch threshold) and lifts without the object is stored
-- with reason 'false_confirm': the estimate failed, not the reach ('miss').
-- SQLite cannot change a CHECK in place: the trials, their traces and their frames
-- are copied into new tables (the children pointing at the new trials), the old ones
-- dropped children first (so no cascade deletes a copied row), and the new ones
-- renamed (the rename rewrites the children's references).
CREATE TABLE grasp_trials_new (
    trial_id            INTEGER PRIMARY KEY,
    session_id          INTEGER NOT NULL REFERENCES grasp_sessions (session_id) ON DELETE CASCADE,
    sigma_index         INTEGER NOT NULL,  -- into the session's σ list
    scene_index         INTEGER NOT NULL,  -- into the session's scenes (0 on a rig)
    object              TEXT    NOT NULL,
    mode                TEXT    NOT NULL CHECK (mode IN ('open', 'closed')),
    trial               INTEGER NOT NULL,  -- 0-based, per object
    medium              TEXT    NOT NULL,
    sigma_m             REAL    NOT NULL,
    dx_m                REAL    NOT NULL,  -- grasp point offset, gripper frame
    dy_m                REAL    NOT NULL,
    dz_m                REAL    NOT NULL,
    commanded_width_m   REAL    NOT NULL,
    final_width_m       REAL    NOT NULL,
    peak_estimate_n     REAL,
    peak_true_n         REAL,
    success             INTEGER NOT NULL CHECK (success IN (0, 1)),
    reason              TEXT CHECK (reason IN ('slip', 'crush', 'miss', 'timeout', 'device_fault', 'estimate_stalled', 'false_confirm', 'refused')),
    detail              TEXT,
    confirmed_after_s   REAL,
    wall_s              REAL    NOT NULL,  -- wall-clock time the trial took
    created_at          TEXT    NOT NULL,
    past_touch_mm       REAL,              -- closed past the calibrated touch
    CHECK ((success = 1) = (reason IS NULL)),
    UNIQUE (session_id, sigma_index, scene_index, object, mode, trial)
);
INSERT INTO grasp_trials_new SELECT
    trial_id, session_id, sigma_index, scene_index, object, mode, trial, medium, sigma_m,
    dx_m, dy_m, dz_m, commanded_width_m, final_width_m, peak_estimate_n, peak_true_n,
    success, reason, detail, confirmed_after_s, wall_s, created_at, past_touch_mm
FROM grasp_trials;

CREATE TABLE grasp_traces_new (
    trial_id        INTEGER PRIMARY KEY REFERENCES grasp_trials_new (trial_id) ON DELETE CASCADE,
    cycles          INTEGER NOT NULL,
    encoding        TEXT    NOT NULL,  -- 'f32le-v1'
    t_s             BLOB    NOT NULL,  -- since the trial's first cycle
    estimate_n      BLOB    NOT NULL,
    true_n          BLOB    NOT NULL,
    measured_count  BLOB    NOT NULL,  -- one byte per cycle
    request_count   BLOB    NOT NULL   -- one byte per cycle
);
INSERT INTO grasp_traces_new SELECT
    trial_id, cycles, encoding, t_s, estimate_n, true_n, measured_count, request_count
FROM grasp_traces;

CREATE TABLE grasp_trial_frames_new (
    trial_id INTEGER NOT NULL REFERENCES grasp_trials_new (trial_id) ON DELETE CASCADE,
    moment   TEXT    NOT NULL CHECK (moment IN ('contact', 'confirmed', 'lifted', 'end')),
    t_s      REAL    NOT NULL,  -- exposure, s after the trial's start
    png      BLOB    NOT NULL CHECK (length(png) > 8),
    PRIMARY KEY (trial_id, moment)
);
INSERT INTO grasp_trial_frames_new SELECT trial_id, moment, t_s, png FROM grasp_trial_frames;

DROP TABLE grasp_trial_frames;
DROP TABLE grasp_traces;
DROP TABLE grasp_trials;
ALTER TABLE grasp_trials_new RENAME TO grasp_trials;
ALTER TABLE grasp_traces_new RENAME TO grasp_traces;
ALTER TABLE grasp_trial_frames_new RENAME TO grasp_trial_frames;
