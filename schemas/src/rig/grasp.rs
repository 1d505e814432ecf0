//! What a lab chooses by hand for grasp trials on its rig (`[grasp]` in the rig file):
//! per object, where the gripper grasps it in the arm's base frame, its open-loop
//! gripping width, how high it is lifted and where it is set down; and where the arm
//! waits between trials. The perturbation of a trial is applied in the grasp pose's
//! own frame (x along the gripping direction, y across the fingers, z along the
//! finger), so `base_from_grasp`'s axes must be the gripper's.

use super::{ArmPose, Medium, WorkspaceBounds};
use crate::config::Check;
use serde::{Deserialize, Serialize};

/// Grasp trials on the rig.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GraspSetup {
    /// What surrounds the objects: `air` (land) or `water` (a tank). Only labels the
    /// session's table; the physics is the rig's.
    pub medium: Medium,
    /// Where the gripper waits between trials and ends every session, base frame.
    pub safe_pose: ArmPose,
    /// How far above a grasp (and a set-down) pose the gripper comes down from, m.
    pub approach_height_m: f64,
    /// Speed of the arm's moves between poses, m/s (the descent to the object and the
    /// set-down run at a quarter of it).
    pub speed_m_s: f64,
    /// The objects.
    pub objects: Vec<GraspObjectSetup>,
}

/// One object of the rig's grasp trials.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GraspObjectSetup {
    /// Its name (as `grasp calibrate --rig … --object` names it).
    pub name: String,
    /// The gripper's pose when it grasps the object unperturbed, base frame.
    pub base_from_grasp: ArmPose,
    /// Open loop: the opening the fingers close to, mm.
    pub open_width_mm: f64,
    /// How high the object is lifted, mm.
    pub lift_mm: f64,
    /// Where the gripper sets it down, base frame; absent: the grasp pose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub place: Option<ArmPose>,
}

impl GraspObjectSetup {
    /// Where the object is set down.
    #[must_use]
    pub fn place_pose(&self) -> ArmPose {
        self.place.unwrap_or(self.base_from_grasp)
    }
}

/// `pose` moved by `dz_m` along the base frame's z (up).
#[must_use]
pub fn raised(pose: &ArmPose, dz_m: f64) -> ArmPose {
    let mut p = *pose;
    p.translation_m[2] += dz_m;
    p
}

/// The Hand-E's stroke, mm (both fingers).
const STROKE_MM: f64 = 50.0;

impl GraspSetup {
    /// The object named `name`.
    #[must_use]
    pub fn object(&self, name: &str) -> Option<&GraspObjectSetup> {
        self.objects.iter().find(|o| o.name == name)
    }

    /// Checks every field against the workspace: each pose, and the poses above it
    /// the trials pass through, inside the reach box.
    pub(super) fn validate_in(&self, w: &WorkspaceBounds, c: &mut Check) {
        c.within(
            "grasp.approach_height_m",
            self.approach_height_m,
            0.005,
            0.5,
            "m",
        );
        c.within("grasp.speed_m_s", self.speed_m_s, 0.001, 0.5, "m/s");
        let reach = |c: &mut Check, field: &str, p: &ArmPose| {
            if !p.is_valid() {
                c.fail(
                    field,
                    "expected finite translation_m and a non-zero rotation_wxyz",
                );
            } else if !w.contains_arm(p) {
                c.fail(
                    field,
                    format!(
                        "{:?} m in the base frame: outside workspace.reach_in_base_m",
                        p.translation_m
                    ),
                );
            }
        };
        reach(c, "grasp.safe_pose", &self.safe_pose);
        if self.objects.is_empty() {
            c.fail(
                "grasp.objects",
                "expected at least one [[grasp.objects]] with name, base_from_grasp, open_width_mm and lift_mm",
            );
        }
        let approach = if self.approach_height_m.is_finite() {
            self.approach_height_m
        } else {
            0.0
        };
        for (i, o) in self.objects.iter().enumerate() {
            let field = |f: &str| format!("grasp.objects[{i}].{f}");
            if o.name.trim().is_empty() {
                c.fail(field("name"), "expected a non-empty name");
            } else if let Some(why) = crate::scene::name_problem(&o.name) {
                c.fail(field("name"), why);
            } else if self.objects[..i].iter().any(|p| p.name == o.name) {
                c.fail(
                    field("name"),
                    format!("`{}` is named twice: expected unique names", o.name),
                );
            }
            c.within(
                &field("open_width_mm"),
                o.open_width_mm,
                0.0,
                STROKE_MM,
                "mm",
            );
            c.within(&field("lift_mm"), o.lift_mm, 1.0, 500.0, "mm");
            reach(c, &field("base_from_grasp"), &o.base_from_grasp);
            reach(
                c,
                &format!("{} raised by approach_height_m", field("base_from_grasp")),
                &raised(&o.base_from_grasp, approach),
            );
            if o.lift_mm.is_finite() {
                reach(
                    c,
                    &format!("{} raised by lift_mm", field("base_from_grasp")),
                    &raised(&o.base_from_grasp, o.lift_mm / 1000.0),
                );
            }
            if let Some(p) = &o.place {
                reach(c, &field("place"), p);
                reach(
                    c,
                    &format!("{} raised by approach_height_m", field("place")),
                    &raised(p, approach),
                );
            }
        }
    }
}
