-- Grasp success-rate trials (`softtouch grasp trials`, the paper's Figure 4).
-- A session is one invocation's plan: the model, the scenes (one per medium), the
-- seed and every setting; its trials are written one transaction each (the trial row
-- and its packed trace together), so a kill -9 loses at most the trial in flight and
-- a resume runs exactly the missing ones.
CREATE TABLE grasp_sessions (
    session_id       INTEGER PRIMARY KEY,
    created_at       TEXT    NOT NULL,  -- wall clock (UTC)
    model            TEXT    NOT NULL,  -- the stored model's name
    seed             INTEGER NOT NULL,
    scenes_json      TEXT    NOT NULL,  -- JSON array of the scenes, as run
    config_json      TEXT    NOT NULL,  -- objects, modes, trials, σ list, loop settings
    software_version TEXT    NOT NULL
);

CREATE TABLE grasp_trials (
    trial_id            INTEGER PRIMARY KEY,
    session_id          INTEGER NOT NULL REFERENCES grasp_sessions (session_id) ON DELETE CASCADE,
    sigma_index         INTEGER NOT NULL,  -- into the session's σ list
    scene_index         INTEGER NOT NULL,  -- into the session's scenes
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
    reason              TEXT CHECK (reason IN ('slip', 'crush', 'miss', 'timeout', 'device_fault')),
    detail              TEXT,
    confirmed_after_s   REAL,
    wall_s              REAL    NOT NULL,  -- wall-clock time the trial took
    created_at          TEXT    NOT NULL,
    CHECK ((success = 1) = (reason IS NULL)),
    UNIQUE (session_id, sigma_index, scene_index, object, mode, trial)
);

-- One row per trial: every cycle packed as little-endian f32 arrays (NaN: none).
CREATE TABLE grasp_traces (
    trial_id        INTEGER PRIMARY KEY REFERENCES grasp_trials (trial_id) ON DELETE CASCADE,
    cycles          INTEGER NOT NULL,
    encoding        TEXT    NOT NULL,  -- 'f32le-v1'
    t_s             BLOB    NOT NULL,  -- since the trial's first cycle
    estimate_n      BLOB    NOT NULL,
    true_n          BLOB    NOT NULL,
    measured_count  BLOB    NOT NULL,  -- one byte per cycle
    request_count   BLOB    NOT NULL   -- one byte per cycle
);
