-- runs.rod_schedule becomes a JSON array of rod names (was: the names joined with
-- commas), so that any name reads back exactly: commas, quotes, unicode, blanks.
-- Every row here predates this migration, so every row is comma-joined: split each
-- at its commas, in order (an empty schedule was one empty name, and stays so).
WITH RECURSIVE split (run_id, n, name, rest) AS (
    SELECT run_id, 0, NULL, rod_schedule || ',' FROM runs
    UNION ALL
    SELECT run_id, n + 1,
           substr(rest, 1, instr(rest, ',') - 1),
           substr(rest, instr(rest, ',') + 1)
    FROM split WHERE rest <> ''
)
UPDATE runs SET rod_schedule = (
    SELECT json_group_array(name)
    FROM (SELECT name FROM split WHERE split.run_id = runs.run_id AND n > 0 ORDER BY n)
);
