-- Images a stored result cannot be redrawn from its tables (the decoder traversals and
-- the paired instances of `softtouch latent`): each PNG under its file name, byte for
-- byte, written in the result's transaction. The report shows them inline.
CREATE TABLE result_figures (
    result_id INTEGER NOT NULL REFERENCES results (result_id) ON DELETE CASCADE,
    name      TEXT    NOT NULL CHECK (length(name) > 0),
    png       BLOB    NOT NULL CHECK (length(png) > 8),
    PRIMARY KEY (result_id, name)
);
