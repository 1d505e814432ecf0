-- How far past the calibrated first touch the fingers closed in a trial, mm: the grip
-- a lab can see on a rig, where no true force is known (issue 66). NULL for trials
-- stored before it was kept.
ALTER TABLE grasp_trials ADD COLUMN past_touch_mm DOUBLE PRECISION;
