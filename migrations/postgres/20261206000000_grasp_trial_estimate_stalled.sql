-- A closed loop that reaches its squeeze bound with the estimate below the target
-- stops there: such a trial is stored with reason 'estimate_stalled'. Same version
-- as migrations/sqlite/20261206000000_grasp_trial_estimate_stalled.sql.
ALTER TABLE grasp_trials DROP CONSTRAINT grasp_trials_reason_check;
ALTER TABLE grasp_trials ADD CONSTRAINT grasp_trials_reason_check
    CHECK (reason IN ('slip', 'crush', 'miss', 'timeout', 'device_fault', 'estimate_stalled', 'refused'));
