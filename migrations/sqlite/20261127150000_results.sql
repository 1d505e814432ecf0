-- Results of the experiment verbs (`grasp follow|disturb|twist`, `bench grasp`,
-- `transfer`, `sweep alpha|latent|finetune`, `latent`): one row per invocation and its
-- tables, written in one transaction as the verb ends, so a kill -9 leaves the whole
-- result or none of it. Nothing is overwritten: a re-run adds a row.
--
-- Layout (documented here, read by `softtouch results` and `softtouch report`):
-- - `settings_json`: a JSON object of what ran, the verb's settings and seeds by flag
--   name (for example {"targets_n":[0.4,1.6,3.0],"seed":7}).
-- - `model`/`model_sha256`: the stored model it ran (sha256 of its artifact), if any;
--   `dataset`: the dataset's name, if any; `scene_hash`/`rig_hash`: sha256 of the
--   scene as run (with camera rate and seed) or of the rig's gripper and cameras.
-- - `software_version`, and `software_commit`: the git commit the binary was built
--   from (with "-dirty" for uncommitted changes), NULL when unknown at build time.
-- - `result_tables`: each CSV the verb writes, under its file name, byte for byte
--   (a header line, then rows; comma-separated, RFC 4180 quoting). The CSV files on
--   disk are exports of these.
CREATE TABLE results (
    result_id        INTEGER PRIMARY KEY,
    created_at       TEXT    NOT NULL,
    verb             TEXT    NOT NULL CHECK (length(verb) > 0),
    settings_json    TEXT    NOT NULL CHECK (json_valid(settings_json)),
    model            TEXT,
    model_sha256     TEXT,
    dataset          TEXT,
    scene_hash       TEXT,
    rig_hash         TEXT,
    summary          TEXT    NOT NULL,
    software_version TEXT    NOT NULL,
    software_commit  TEXT
);

CREATE TABLE result_tables (
    result_id INTEGER NOT NULL REFERENCES results (result_id) ON DELETE CASCADE,
    name      TEXT    NOT NULL CHECK (length(name) > 0),
    csv       TEXT    NOT NULL,
    PRIMARY KEY (result_id, name)
);

CREATE INDEX results_by_verb ON results (verb, result_id);
