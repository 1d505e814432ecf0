-- A run's device time continues across a resume. time_base_ns is the run's clock
-- (ns) when its latest stored sample was done (its retreat home finished), i.e. when
-- the next sample begins; written in the same transaction as that sample, so a kill
-- never leaves it behind the samples. NULL: no sample stored yet (a run starts at 0).
ALTER TABLE runs ADD COLUMN time_base_ns INTEGER CHECK (time_base_ns IS NULL OR time_base_ns >= 0);
