-- A closed loop that confirms its force on an estimate the fingers never felt and
-- lifts without the object is stored with reason 'false_confirm'. Same version as
-- migrations/sqlite/20261209000000_grasp_trial_false_confirm.sql.
ALTER TABLE grasp_trials DROP CONSTRAINT grasp_trials_reason_check;
ALTER TABLE grasp_trials ADD CONSTRAINT grasp_trials_reason_check
    CHECK (reason IN ('slip', 'crush', 'miss', 'timeout', 'device_fault', 'estimate_stalled', 'false_confirm', 'refused'));
