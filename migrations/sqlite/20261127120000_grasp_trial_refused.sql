-- A rig's grasp trial whose perturbed pose lies outside the workspace is refused
-- before anything moves, and stored as such (reason 'refused'), so the table shows
-- it and a resume does not run it again; it is counted in no success rate.
-- SQLite cannot change a CHECK in place: both tables are copied into new ones (the
-- traces pointing at the new trials), the old ones dropped child first (so no
-- cascade deletes a copied trace), and the new ones renamed (the rename rewrites
-- the traces' reference).
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
    reason              TEXT CHECK (reason IN ('slip', 'crush', 'miss', 'timeout', 'device_fault', 'refused')),
    detail              TEXT,
    confirmed_after_s   REAL,
    wall_s              REAL    NOT NULL,  -- wall-clock time the trial took
    created_at          TEXT    NOT NULL,
    CHECK ((success = 1) = (reason IS NULL)),
    UNIQUE (session_id, sigma_index, scene_index, object, mode, trial)
);
INSERT INTO grasp_trials_new SELECT
    trial_id, session_id, sigma_index, scene_index, object, mode, trial, medium, sigma_m,
    dx_m, dy_m, dz_m, commanded_width_m, final_width_m, peak_estimate_n, peak_true_n,
    success, reason, detail, confirmed_after_s, wall_s, created_at
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

DROP TABLE grasp_traces;
DROP TABLE grasp_trials;
ALTER TABLE grasp_trials_new RENAME TO grasp_trials;
ALTER TABLE grasp_traces_new RENAME TO grasp_traces;
