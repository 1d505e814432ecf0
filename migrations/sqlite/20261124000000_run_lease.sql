-- One writer per run: the process collecting a run holds its lease. Another process
-- is refused while the holder lives; a stale lease (its process dead, or no heartbeat
-- for long) is taken over, and the takeover is an event of the run.
CREATE TABLE run_leases (
    run_id       INTEGER PRIMARY KEY REFERENCES runs (run_id) ON DELETE CASCADE,
    holder       TEXT    NOT NULL,  -- unique per collection job: "pid-host-nanos"
    pid          INTEGER NOT NULL,
    host         TEXT    NOT NULL,
    acquired_at  TEXT    NOT NULL,  -- wall clock (UTC)
    heartbeat_at TEXT    NOT NULL   -- wall clock (UTC), renewed after every sample
);
