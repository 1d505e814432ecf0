//! Method S3: the predicted wrench, rotated from the finger-base frame B to the world
//! frame W, projected on the gripping direction:
//! `F_est = [0 0 0; 0 1 0; 0 0 0] · [ᵂR_B 0₃ₓ₃] · ᴮF`.

use softtouch_schemas::{ArmPose, Wrench};

use crate::GraspError;

/// How a finger is mounted: where its base frame B sits in the world frame W, and the
/// world direction along which the object pushes the finger while gripped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    /// `ᵂT_B`: the finger base (the force sensor's frame in the training data) in W.
    pub world_from_finger_base: ArmPose,
    /// The gripping direction in W (the paper's Y of W), not necessarily unit length;
    /// a squeezing grip projects positive on it.
    pub gripping_direction_in_world: [f64; 3],
}

impl Projection {
    /// The paper's setting: the gripping direction is W's Y.
    pub fn along_world_y(world_from_finger_base: ArmPose) -> Result<Self, GraspError> {
        Self::new(world_from_finger_base, [0.0, 1.0, 0.0])
    }

    /// A projection; the direction must have a usable length and the pose be valid.
    pub fn new(
        world_from_finger_base: ArmPose,
        gripping_direction_in_world: [f64; 3],
    ) -> Result<Self, GraspError> {
        let norm = gripping_direction_in_world
            .iter()
            .map(|d| d * d)
            .sum::<f64>()
            .sqrt();
        if !(norm.is_finite() && norm > 1e-9) {
            return Err(GraspError::Config(format!(
                "gripping_direction_in_world {gripping_direction_in_world:?}: expected a finite, non-zero vector"
            )));
        }
        if !world_from_finger_base.is_valid() {
            return Err(GraspError::Config(format!(
                "world_from_finger_base {world_from_finger_base:?}: expected finite values and a non-degenerate quaternion"
            )));
        }
        Ok(Self {
            world_from_finger_base,
            gripping_direction_in_world,
        })
    }

    /// The grip force in N: the force part of `wrench_in_finger_base` in W, along the
    /// gripping direction. Only the rotation matters (a force does not change when its
    /// frame is moved). `None` for a non-finite wrench: it must never move a device.
    #[must_use]
    pub fn grip_force_n(&self, wrench_in_finger_base: &Wrench) -> Option<f64> {
        if !wrench_in_finger_base.is_finite() {
            return None;
        }
        let force_in_world = self
            .world_from_finger_base
            .rotate(wrench_in_finger_base.force_n);
        let w = Wrench {
            force_n: force_in_world,
            torque_nm: [0.0; 3],
        };
        w.force_along(self.gripping_direction_in_world)
            .ok()
            .filter(|f| f.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn the_projection_rotates_the_force_into_the_world_and_keeps_its_y_part() {
        // Finger base turned −90° about z: its −x (the push of an object met along
        // +x) is the world's +y.
        let p =
            Projection::along_world_y(ArmPose::from_translation_yaw([0.1, 0.2, 0.3], -FRAC_PI_2))
                .expect("valid");
        let w = Wrench::from_array([-2.0, 0.5, 7.0, 0.1, 0.2, 0.3]);
        let f = p.grip_force_n(&w).expect("finite");
        assert!((f - 2.0).abs() < 1e-9, "{f}");
        // Identity mount: F_y itself, torques ignored.
        let id = Projection::along_world_y(ArmPose::default()).expect("valid");
        let f = id.grip_force_n(&w).expect("finite");
        assert!((f - 0.5).abs() < 1e-12, "{f}");
        // The direction is normalised.
        let scaled = Projection::new(ArmPose::default(), [0.0, 4.0, 0.0]).expect("valid");
        let f2 = scaled.grip_force_n(&w).expect("finite");
        assert!((f2 - 0.5).abs() < 1e-12, "{f2}");
    }

    #[test]
    fn a_nan_wrench_or_a_degenerate_direction_gives_no_force() {
        let p = Projection::along_world_y(ArmPose::default()).expect("valid");
        assert_eq!(
            p.grip_force_n(&Wrench::from_array([f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0])),
            None
        );
        let err = Projection::new(ArmPose::default(), [0.0, 0.0, 0.0]).expect_err("zero");
        assert!(
            err.to_string().contains("gripping_direction_in_world"),
            "{err}"
        );
        let err = Projection::new(ArmPose::default(), [f64::NAN, 1.0, 0.0]).expect_err("nan");
        assert!(err.to_string().contains("finite"), "{err}");
    }
}
