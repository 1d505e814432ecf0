-- Frames of the finger at rest (no contact: the arm at home, the force/torque sensor
-- just zeroed), taken once at a run's start, as each sample's frame is stored. What an
-- image tare for a medium compares (`transfer --tare`): a water run's rest frames
-- against those of the land runs a model learned from, with no water label. A run
-- stored before this migration has none.
CREATE TABLE rest_frames (
    run_id     BIGINT NOT NULL REFERENCES runs (run_id) ON DELETE CASCADE,
    rest_index BIGINT NOT NULL CHECK (rest_index >= 0),
    format     TEXT   NOT NULL CHECK (format IN ('png', 'jpeg', 'rgb8')),
    width      BIGINT NOT NULL CHECK (width > 0),
    height     BIGINT NOT NULL CHECK (height > 0),
    sequence   BIGINT NOT NULL,
    t_ns       BIGINT NOT NULL,
    data       BYTEA  NOT NULL CHECK (length(data) > 0),
    PRIMARY KEY (run_id, rest_index)
);
ALTER TABLE rest_frames ALTER COLUMN data SET STORAGE EXTERNAL;
