-- softtouch store: curated datasets and imported runs.
-- A dataset is a named, fixed selection of samples from one or more runs with a split
-- (train / val / test) per sample. Its definition (runs, filters, ratio, seed) is kept
-- as JSON for people and provenance; the member rows are the truth, so a dataset never
-- changes when code or filters change later.

CREATE TABLE datasets (
    dataset_id       INTEGER PRIMARY KEY,
    name             TEXT    NOT NULL UNIQUE CHECK (length(name) > 0),
    definition_json  TEXT    NOT NULL,  -- {"runs": [...], "filters": {...}, "split": "7:1:2", "seed": ...}
    seed             INTEGER NOT NULL,  -- bit pattern of a u64, like runs.seed
    split_ratio      TEXT    NOT NULL,  -- e.g. '7:1:2' (train:val:test)
    sample_count     INTEGER NOT NULL CHECK (sample_count > 0),
    software_version TEXT    NOT NULL,
    schema_version   INTEGER NOT NULL,
    created_at       TEXT    NOT NULL   -- ISO-8601 UTC
);

-- One row per sample in a dataset. `position` is the dataset's own order (export
-- order, image file names); it is 0..sample_count-1 without gaps.
CREATE TABLE dataset_members (
    dataset_id   INTEGER NOT NULL REFERENCES datasets (dataset_id) ON DELETE CASCADE,
    position     INTEGER NOT NULL CHECK (position >= 0),
    run_id       INTEGER NOT NULL,
    sample_index INTEGER NOT NULL,
    split        TEXT    NOT NULL CHECK (split IN ('train', 'val', 'test')),
    PRIMARY KEY (dataset_id, position),
    UNIQUE (dataset_id, run_id, sample_index),
    FOREIGN KEY (run_id, sample_index) REFERENCES samples (run_id, sample_index)
) WITHOUT ROWID;

CREATE INDEX dataset_members_by_sample ON dataset_members (run_id, sample_index);

-- Runs that were not collected here but imported from files (`softtouch dataset
-- import`): where they came from. `origin_run_id` is the run's id in the database it
-- was exported from (NULL for the paper's layout); exports show it in their `run`
-- column so that export → import → export gives the same files.
CREATE TABLE run_imports (
    run_id        INTEGER PRIMARY KEY REFERENCES runs (run_id) ON DELETE CASCADE,
    layout        TEXT    NOT NULL CHECK (layout IN ('softtouch-export', 'paper-csv')),
    source_path   TEXT    NOT NULL,
    origin_run_id INTEGER,
    provenance    TEXT    NOT NULL,  -- JSON: the manifest's record of the run, or a note
    imported_at   TEXT    NOT NULL
);
