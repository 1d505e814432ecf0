-- softtouch store, schema 1.
-- Units are SI (m, rad, N, N·m, ns on the run's monotonic clock). Wall-clock times
-- (created_at, ...) are ISO-8601 UTC text, for people only.

CREATE TABLE runs (
    run_id           INTEGER PRIMARY KEY,
    status           TEXT    NOT NULL CHECK (status IN ('running', 'completed', 'stopped', 'failed')),
    seed             INTEGER NOT NULL,
    samples_planned  INTEGER NOT NULL CHECK (samples_planned >= 0),
    rod_schedule     TEXT    NOT NULL,  -- rod names, comma-separated, taken in blocks
    rod_block        INTEGER NOT NULL CHECK (rod_block >= 1),  -- samples per rod block
    scene_name       TEXT    NOT NULL,
    medium           TEXT    NOT NULL CHECK (medium IN ('air', 'water')),
    rig_toml         TEXT    NOT NULL,  -- resolved rig config, replayable
    scene_toml       TEXT    NOT NULL,  -- resolved scene spec, replayable
    software_version TEXT    NOT NULL,
    schema_version   INTEGER NOT NULL,
    created_at       TEXT    NOT NULL,
    updated_at       TEXT    NOT NULL,
    finished_at      TEXT
);

CREATE TABLE samples (
    run_id          INTEGER NOT NULL REFERENCES runs (run_id) ON DELETE CASCADE,
    sample_index    INTEGER NOT NULL CHECK (sample_index >= 0),
    rod             TEXT    NOT NULL,
    medium          TEXT    NOT NULL CHECK (medium IN ('air', 'water')),
    cmd_x_m         REAL    NOT NULL,
    cmd_z_m         REAL    NOT NULL,
    cmd_theta_rad   REAL    NOT NULL,
    meas_x_m        REAL,
    meas_z_m        REAL,
    meas_theta_rad  REAL,
    -- mean wrench over the window, sensor frame
    fx_n            REAL    NOT NULL,
    fy_n            REAL    NOT NULL,
    fz_n            REAL    NOT NULL,
    tx_nm           REAL    NOT NULL,
    ty_nm           REAL    NOT NULL,
    tz_nm           REAL    NOT NULL,
    -- per-axis standard deviation over the window
    fx_std_n        REAL    NOT NULL CHECK (fx_std_n >= 0),
    fy_std_n        REAL    NOT NULL CHECK (fy_std_n >= 0),
    fz_std_n        REAL    NOT NULL CHECK (fz_std_n >= 0),
    tx_std_nm       REAL    NOT NULL CHECK (tx_std_nm >= 0),
    ty_std_nm       REAL    NOT NULL CHECK (ty_std_nm >= 0),
    tz_std_nm       REAL    NOT NULL CHECK (tz_std_nm >= 0),
    reading_count   INTEGER NOT NULL CHECK (reading_count >= 0),
    frame_t_ns      INTEGER NOT NULL,
    window_start_ns INTEGER NOT NULL,
    window_end_ns   INTEGER NOT NULL CHECK (window_end_ns >= window_start_ns),
    sync_skew_ns    INTEGER NOT NULL,
    status          TEXT    NOT NULL CHECK (status IN ('ok', 'rejected')),
    reject_reason   TEXT    CHECK ((status = 'ok') = (reject_reason IS NULL)),
    attempts        INTEGER NOT NULL CHECK (attempts >= 1),
    PRIMARY KEY (run_id, sample_index)
) WITHOUT ROWID;

CREATE INDEX samples_by_status ON samples (run_id, status);

-- The frame paired with a sample: exactly one per sample.
CREATE TABLE frames (
    run_id       INTEGER NOT NULL,
    sample_index INTEGER NOT NULL,
    format       TEXT    NOT NULL CHECK (format IN ('png', 'jpeg', 'rgb8')),
    width        INTEGER NOT NULL CHECK (width > 0),
    height       INTEGER NOT NULL CHECK (height > 0),
    sequence     INTEGER NOT NULL,
    t_ns         INTEGER NOT NULL,
    data         BLOB    NOT NULL CHECK (length(data) > 0),
    PRIMARY KEY (run_id, sample_index),
    FOREIGN KEY (run_id, sample_index) REFERENCES samples (run_id, sample_index) ON DELETE CASCADE
);

-- The raw force/torque readings of a sample's window, packed (encoding 'ftw1':
-- per reading, little-endian: u64 t_ns, u32 rdt_sequence, u32 ft_sequence, u32 status,
-- 6 × f64 Fx Fy Fz [N] Tx Ty Tz [N·m]; 68 bytes).
CREATE TABLE ft_windows (
    run_id        INTEGER NOT NULL,
    sample_index  INTEGER NOT NULL,
    encoding      TEXT    NOT NULL CHECK (encoding = 'ftw1'),
    reading_count INTEGER NOT NULL CHECK (reading_count >= 0),
    data          BLOB    NOT NULL CHECK (length(data) = reading_count * 68),
    PRIMARY KEY (run_id, sample_index),
    FOREIGN KEY (run_id, sample_index) REFERENCES samples (run_id, sample_index) ON DELETE CASCADE
);

-- Faults, recoveries and other things worth knowing about a run.
CREATE TABLE events (
    event_id     INTEGER PRIMARY KEY,
    run_id       INTEGER NOT NULL REFERENCES runs (run_id) ON DELETE CASCADE,
    sample_index INTEGER,
    t_ns         INTEGER,           -- run clock, where known
    created_at   TEXT    NOT NULL,  -- wall clock
    level        TEXT    NOT NULL CHECK (level IN ('info', 'warn', 'error')),
    kind         TEXT    NOT NULL,
    message      TEXT    NOT NULL
);

CREATE INDEX events_by_run ON events (run_id, event_id);
