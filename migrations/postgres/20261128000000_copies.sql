-- `softtouch db copy`: this store's identity, and what was copied into it from where
-- (see store/src/copy.rs). Same version as migrations/sqlite/20261128000000_copies.sql.
CREATE TABLE store_identity (
    singleton BIGINT PRIMARY KEY CHECK (singleton = 1),
    uid       TEXT   NOT NULL CHECK (length(uid) > 0)
);

CREATE TABLE copied (
    source_uid TEXT   NOT NULL,
    kind       TEXT   NOT NULL,
    source_id  BIGINT NOT NULL,
    dest_id    BIGINT NOT NULL,
    PRIMARY KEY (source_uid, kind, source_id)
);
