-- softtouch store: trained models.
-- A model is the artifact of one training (weights with config, preprocessing and
-- label normalisation; format in trainer/src/artifact.rs) and the record of how it
-- was made: on which dataset, with which hyper-parameters, and how well it did.

CREATE TABLE models (
    model_id         INTEGER PRIMARY KEY,
    name             TEXT    NOT NULL UNIQUE CHECK (length(name) > 0),
    dataset_id       INTEGER REFERENCES datasets (dataset_id) ON DELETE SET NULL,
    dataset_name     TEXT    NOT NULL,  -- kept when the dataset is deleted
    kind             TEXT    NOT NULL CHECK (kind IN ('svae', 'vae', 'convnet')),
    config_json      TEXT    NOT NULL,  -- model config incl. preprocessing (ModelConfig)
    train_json       TEXT    NOT NULL,  -- optimisation settings (TrainConfig)
    metrics_json     TEXT    NOT NULL,  -- validation and test metrics, epochs, timing
    history_json     TEXT    NOT NULL,  -- one entry per epoch
    test_r2_mean     REAL,              -- NULL for the VAE
    test_image_mse   REAL,              -- NULL for the ConvNet
    artifact         BLOB    NOT NULL CHECK (length(artifact) > 16),
    software_version TEXT    NOT NULL,
    created_at       TEXT    NOT NULL
);
