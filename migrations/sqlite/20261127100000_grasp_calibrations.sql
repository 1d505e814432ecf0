-- Stiffness calibrations from the finger's own estimate (`softtouch grasp calibrate`,
-- and the grasp verbs when no stored one matches): one row per closing on a reference
-- object. `setup_kind` says what `setup_hash` fingerprints: a scene (with the camera
-- rate and seed) or a rig file. The curve is JSON: `points_json` is
-- [[requested count, measured count, F_est in N or null], ...] in closing order,
-- `lambda_json` is [[window centre count, Λ in N/mm], ...] (Theil–Sen per window).
CREATE TABLE grasp_calibrations (
    calibration_id INTEGER PRIMARY KEY,
    created_at TEXT NOT NULL,
    setup_kind TEXT NOT NULL CHECK (setup_kind IN ('scene', 'rig')),
    setup_hash TEXT NOT NULL,
    model TEXT NOT NULL,
    model_sha256 TEXT NOT NULL,
    object TEXT NOT NULL,
    touch_count INTEGER NOT NULL CHECK (touch_count BETWEEN 0 AND 255),
    lambda_max_n_per_mm REAL NOT NULL,
    lambda_iqr_lo_n_per_mm REAL NOT NULL,
    lambda_iqr_hi_n_per_mm REAL NOT NULL,
    counts_spanned INTEGER NOT NULL,
    baseline_n REAL NOT NULL,
    mm_per_count REAL NOT NULL,
    ended TEXT NOT NULL,
    points_json TEXT NOT NULL,
    lambda_json TEXT NOT NULL,
    -- The simulator's true Λ_max over the same range, for comparison only (NULL on a rig).
    true_lambda_max_n_per_mm REAL,
    software_version TEXT NOT NULL
);

CREATE INDEX grasp_calibrations_match
    ON grasp_calibrations (setup_hash, model_sha256, object, calibration_id);
