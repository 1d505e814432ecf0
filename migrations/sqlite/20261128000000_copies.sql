-- `softtouch db copy`: this store's identity, and what was copied into it from where
-- (see store/src/copy.rs). Same version as migrations/postgres/20261128000000_copies.sql.
CREATE TABLE store_identity (
    singleton INTEGER PRIMARY KEY CHECK (singleton = 1),
    uid       TEXT    NOT NULL CHECK (length(uid) > 0)
);

CREATE TABLE copied (
    source_uid TEXT    NOT NULL,  -- the source store's store_identity.uid
    kind       TEXT    NOT NULL,  -- run, event, dataset, model, calibration, session, trial, result
    source_id  INTEGER NOT NULL,
    dest_id    INTEGER NOT NULL,
    PRIMARY KEY (source_uid, kind, source_id)
);
