//! The stiffness calibration on the simulated soft grasp, through the same devices a
//! loop uses: with an estimator that reads the truth its Λ_max and first touch match
//! the simulator's own curve; with a poor one (half the force, and noise) they are
//! visibly off; the fingers always end back where the closing started.

use softtouch_drivers::{Clock, Frame, Gripper, TokioClock};
use softtouch_grasp::{
    ForceEstimator, GraspError, Projection, StiffnessConfig, Stroke, calibrate_stiffness,
    check_gain,
};
use softtouch_schemas::scene::ObjectProfile;
use softtouch_schemas::{ArmPose, RodShape, Wrench};
use softtouch_sim::{GraspObject, SoftGraspHandle, soft_grasp};
use std::sync::Arc;

/// The simulator's true wrench on finger 0, times `gain`, plus `noise_n` of a
/// deterministic ±1 pattern on the grip axis (a poorer model).
struct Reader {
    handle: SoftGraspHandle,
    gain: f64,
    noise_n: f64,
    k: u64,
}

impl ForceEstimator for Reader {
    fn estimate(&mut self, frame: &Frame) -> Result<Option<Wrench>, GraspError> {
        let mut w = self
            .handle
            .true_wrench(frame.meta.t)
            .map_err(|e| GraspError::Estimate(e.to_string()))?;
        self.k += 1;
        let wobble = if self.k.is_multiple_of(3) { 1.0 } else { -0.5 };
        for f in &mut w.force_n {
            *f *= self.gain;
        }
        // The finger's push is its −x (the grip axis after the projection).
        w.force_n[0] -= self.noise_n * wobble;
        Ok(Some(w))
    }
}

fn projection() -> Projection {
    Projection::along_world_y(ArmPose::from_translation_yaw(
        [0.0; 3],
        -std::f64::consts::FRAC_PI_2,
    ))
    .expect("projection")
}

fn bottle() -> GraspObject {
    GraspObject::standing(
        "bottle",
        RodShape::Circle,
        0.03,
        1.0,
        ObjectProfile::Prism { height_m: 0.2 },
    )
}

async fn calibrate(
    gain: f64,
    noise_n: f64,
) -> (softtouch_grasp::StiffnessCalibration, f64, u8, u8) {
    let clock = TokioClock::new();
    let object = bottle();
    let (mut gripper, mut camera, handle) = soft_grasp(
        &softtouch_schemas::defaults::scene(),
        object.clone(),
        120.0,
        0,
        clock,
    )
    .expect("grasp");
    let mut reader = Reader {
        handle: handle.clone(),
        gain,
        noise_n,
        k: 0,
    };
    let config = StiffnessConfig {
        start_count: softtouch_drivers::gripper::position_for_opening(
            object.width_m * 1000.0 + 10.0,
        ),
        ..StiffnessConfig::default()
    };
    let shared: Arc<dyn Clock> = Arc::new(clock);
    let cal = calibrate_stiffness(
        &mut gripper,
        &mut camera,
        &mut reader,
        &projection(),
        &Stroke::default(),
        shared.as_ref(),
        &config,
    )
    .await
    .expect("calibrates");
    let touch = handle.contact_count(0.05).expect("sim").expect("touched");
    let truth = handle
        .max_stiffness_n_per_mm(touch, cal.points.last().expect("points").measured)
        .expect("truth");
    let end = gripper.status().await.expect("status");
    (cal, truth, touch, end.requested_position)
}

#[tokio::test(start_paused = true)]
async fn a_good_estimate_finds_the_true_stiffness_and_a_poor_one_does_not() {
    let (good, truth, touch, back) = calibrate(1.0, 0.0).await;
    let start = good.points[0].request;
    assert_eq!(back, start, "the fingers end where the closing started");
    assert!(
        good.touch_count.abs_diff(touch) <= 2,
        "touch {} against the simulator's {touch}",
        good.touch_count
    );
    let err = (good.lambda_max_n_per_mm - truth).abs() / truth;
    eprintln!(
        "perfect reader: Λ_max {:.3} N/mm (IQR {:.3}–{:.3}) against the simulator's {truth:.3}: {:.1} %",
        good.lambda_max_n_per_mm,
        good.lambda_max_iqr.0,
        good.lambda_max_iqr.1,
        err * 100.0
    );
    assert!(err < 0.10, "within 10 % of the truth: {err}");
    // Half the force and a wobble of ±0.1 N: Λ_max about half, and K = 0.75 of it
    // is then at most 0.375 of the truth: Method S4 says the loop may not converge.
    let (poor, truth, _, _) = calibrate(0.5, 0.1).await;
    let ratio = poor.lambda_max_n_per_mm / truth;
    eprintln!(
        "poor reader: Λ_max {:.3} N/mm, {:.2} of the truth",
        poor.lambda_max_n_per_mm, ratio
    );
    assert!(ratio < 0.7, "visibly off: {ratio}");
    let k = 0.75 * poor.lambda_max_n_per_mm;
    assert!(matches!(
        check_gain(k, truth).expect("check"),
        softtouch_grasp::GainCheck::MayNotConverge { .. }
    ));
}
