//! The rig's check: every field against what its device and the procedure can do,
//! each problem naming the field and what would work.

use super::*;

impl Validate for RigConfig {
    fn validate(&self, c: &mut Check) {
        match &self.arm {
            ArmDevice::Sim { reflex_force_n } => {
                c.positive("arm.reflex_force_n", *reflex_force_n, "N")
            }
            ArmDevice::Franka {
                address,
                reflex_force_n,
                reflex_torque_nm,
                realtime: _,
                end_effector,
                payload,
                joint_torque_thresholds_nm,
                motion_margin,
            } => {
                non_empty(c, "arm.address", address);
                if let Some(m) = motion_margin {
                    c.within(
                        "arm.motion_margin",
                        *m,
                        0.01,
                        1.0,
                        "(a share of the robot's limits)",
                    );
                }
                if let Some(t) = joint_torque_thresholds_nm
                    && let Err(e) = check_joint_thresholds(t)
                {
                    c.fail("arm.joint_torque_thresholds_nm", e);
                }
                c.positive("arm.reflex_force_n", *reflex_force_n, "N");
                if let Some(t) = reflex_torque_nm {
                    c.positive("arm.reflex_torque_nm", *t, "N·m");
                }
                if let Some(ee) = end_effector {
                    let far = ee.translation_m.iter().any(|v| v.abs() > 0.5);
                    if !ee.is_valid() || far {
                        c.fail(
                            "arm.end_effector",
                            format!(
                                "expected finite translation_m within 0.5 m per axis and a finite, non-zero rotation_wxyz (normalised on use), found {:?} m, {:?}",
                                ee.translation_m, ee.rotation_wxyz
                            ),
                        );
                    }
                }
                if let Some(p) = payload {
                    c.within(
                        "arm.payload.mass_kg",
                        p.mass_kg,
                        0.0,
                        FRANKA_MAX_PAYLOAD_KG,
                        "kg",
                    );
                    for (i, v) in p.com_in_flange_m.iter().enumerate() {
                        c.within(
                            &format!("arm.payload.com_in_flange_m[{i}]"),
                            *v,
                            -0.5,
                            0.5,
                            "m",
                        );
                    }
                    if p.inertia_kg_m2.iter().any(|v| !v.is_finite()) {
                        c.fail(
                            "arm.payload.inertia_kg_m2",
                            "expected 9 finite values, kg·m²",
                        );
                    }
                }
            }
        }
        match &self.force_sensor {
            ForceSensorDevice::Sim { rate_hz } => {
                c.within("force_sensor.rate_hz", *rate_hz, 1.0, 7000.0, "Hz")
            }
            ForceSensorDevice::NetFt {
                address,
                rate_hz,
                counts_per_force,
                counts_per_torque,
                latency_s,
            } => {
                latency(c, "force_sensor.latency_s", *latency_s);
                non_empty(c, "force_sensor.address", address);
                c.within("force_sensor.rate_hz", *rate_hz, 1.0, 7000.0, "Hz");
                if let Some(v) = counts_per_force {
                    c.positive("force_sensor.counts_per_force", *v, "counts/N");
                }
                if let Some(v) = counts_per_torque {
                    c.positive("force_sensor.counts_per_torque", *v, "counts/N·m");
                }
            }
            ForceSensorDevice::AtiSerial {
                port,
                baud,
                counts_per_force,
                counts_per_torque,
                latency_s,
            } => {
                latency(c, "force_sensor.latency_s", *latency_s);
                non_empty(c, "force_sensor.port", port);
                if *baud == 0 {
                    c.fail(
                        "force_sensor.baud",
                        "expected a baud rate > 0 (9600 or 38400 typical)",
                    );
                }
                c.positive(
                    "force_sensor.counts_per_force",
                    *counts_per_force,
                    "counts/N",
                );
                c.positive(
                    "force_sensor.counts_per_torque",
                    *counts_per_torque,
                    "counts/N·m",
                );
            }
        }
        match &self.camera {
            CameraDevice::Sim { fps } => c.within("camera.fps", *fps, 1.0, 1000.0, "frames/s"),
            CameraDevice::V4l {
                device,
                latency_s,
                image,
            } => {
                non_empty(c, "camera.device", device);
                latency(c, "camera.latency_s", *latency_s);
                image_settings(c, "camera.image", image.as_ref());
            }
        }
        match (&self.camera, &self.second_camera) {
            (_, None) => {}
            (CameraDevice::Sim { .. }, Some(CameraDevice::Sim { fps })) => {
                c.within("second_camera.fps", *fps, 1.0, 1000.0, "frames/s");
            }
            (
                CameraDevice::V4l { device: first, .. },
                Some(CameraDevice::V4l {
                    device,
                    latency_s,
                    image,
                }),
            ) => {
                non_empty(c, "second_camera.device", device);
                latency(c, "second_camera.latency_s", *latency_s);
                image_settings(c, "second_camera.image", image.as_ref());
                if device == first {
                    c.fail(
                        "second_camera.device",
                        format!("expected another device than camera.device ({first})"),
                    );
                }
            }
            (_, Some(_)) => c.fail(
                "second_camera.driver",
                "expected the same driver as camera (both \"sim\" or both \"v4l\")",
            ),
        }
        match &self.gripper {
            GripperDevice::Sim {} => {}
            GripperDevice::HandE { port, slave_id } => {
                non_empty(c, "gripper.port", port);
                if !(1..=247).contains(slave_id) {
                    c.fail(
                        "gripper.slave_id",
                        format!("expected a Modbus slave id in [1, 247], found {slave_id}"),
                    );
                }
            }
        }

        let w = &self.workspace;
        c.range("workspace.x_m", &w.x_m, "m");
        c.range("workspace.z_m", &w.z_m, "m");
        c.range("workspace.theta_rad", &w.theta_rad, "rad");
        for (i, axis) in ["x", "y", "z"].iter().enumerate() {
            c.range(
                &format!("workspace.reach_in_base_m[{i}] ({axis})"),
                &w.reach_in_base_m[i],
                "m",
            );
        }
        if !w.base_from_rod.is_valid() {
            c.fail(
                "workspace.base_from_rod",
                "expected finite translation and a non-zero quaternion",
            );
        } else if !w.home.is_finite() {
            c.fail("workspace.home", "expected finite x_m, z_m, theta_rad");
        } else {
            let home = ArmPose::from_contact(&w.base_from_rod, &w.home);
            if !w.contains_arm(&home) {
                c.fail(
                    "workspace.home",
                    format!(
                        "home maps to {:?} m in the base frame, outside workspace.reach_in_base_m",
                        home.translation_m
                    ),
                );
            }
            // Every corner of the contact box must be reachable.
            if c.problems().is_empty() {
                for x in [w.x_m.min, w.x_m.max] {
                    for z in [w.z_m.min, w.z_m.max] {
                        let corner = ContactPose {
                            x_m: x,
                            z_m: z,
                            theta_rad: 0.0,
                        };
                        let p = ArmPose::from_contact(&w.base_from_rod, &corner);
                        if !w.contains_arm(&p) {
                            c.fail(
                                "workspace.reach_in_base_m",
                                format!("contact corner (x={x} m, z={z} m) maps to {:?} m, outside the reach box", p.translation_m),
                            );
                        }
                    }
                }
            }
        }

        if let Some(g) = &self.grasp {
            g.validate_in(w, c);
        }

        let l = &self.limits;
        c.positive("limits.max_force_n", l.max_force_n, "N");
        c.positive("limits.max_torque_nm", l.max_torque_nm, "N·m");
        for i in 0..3 {
            c.positive(
                &format!("limits.sensor_range_force_n[{i}]"),
                l.sensor_range_force_n[i],
                "N",
            );
            c.positive(
                &format!("limits.sensor_range_torque_nm[{i}]"),
                l.sensor_range_torque_nm[i],
                "N·m",
            );
        }

        let p = &self.procedure;
        c.within(
            "procedure.approach_speed_m_s",
            p.approach_speed_m_s,
            1e-4,
            FRANKA_MAX_SPEED_M_S,
            "m/s",
        );
        c.within(
            "procedure.slow_approach_m",
            p.slow_approach_m,
            0.0,
            0.05,
            "m",
        );
        c.within(
            "procedure.slow_approach_speed_m_s",
            p.slow_approach_speed_m_s,
            1e-4,
            p.approach_speed_m_s.max(1e-4),
            "m/s (at most procedure.approach_speed_m_s)",
        );
        c.within(
            "procedure.retreat_speed_m_s",
            p.retreat_speed_m_s,
            1e-4,
            FRANKA_MAX_SPEED_M_S,
            "m/s",
        );
        c.within(
            "procedure.travel_speed_m_s",
            p.travel_speed_m_s,
            1e-4,
            FRANKA_MAX_SPEED_M_S,
            "m/s",
        );
        c.within("procedure.standoff_m", p.standoff_m, 0.0, 0.1, "m");
        c.within("procedure.settle_s", p.settle_s, 0.0, MAX_DURATION_S, "s");
        c.within(
            "procedure.ft_window_s",
            p.ft_window_s,
            1e-4,
            FT_BUFFER_S / 2.0,
            "s (half the force/torque buffer)",
        );
        c.positive("procedure.frame_timeout_s", p.frame_timeout_s, "s");
        if p.frame_timeout_s > MAX_DURATION_S {
            c.fail(
                "procedure.frame_timeout_s",
                format!(
                    "expected at most {MAX_DURATION_S} s, found {}",
                    p.frame_timeout_s
                ),
            );
        }
        if p.min_window_readings == 0 {
            c.fail(
                "procedure.min_window_readings",
                "expected at least 1 reading",
            );
        }
        // A window of length w on a grid of period 1/rate holds at most rate·w + 1
        // readings: more can never be met, and every sample would be rejected. The
        // rate is the slowest a working sensor streams (an ATI serial box's baud rate
        // caps it far below what the box can do).
        let rate_hz = self.force_sensor.rate_hz();
        let least_hz = self.force_sensor.least_rate_hz();
        let why = if least_hz < rate_hz {
            format!(
                "the slowest rate of force_sensor: {least_hz:.1} Hz, what its baud rate carries"
            )
        } else {
            format!("force_sensor rate {least_hz} Hz")
        };
        if least_hz.is_finite() && p.ft_window_s.is_finite() && least_hz > 0.0 {
            let most = (least_hz * p.ft_window_s).floor() + 1.0;
            if f64::from(p.min_window_readings) > most {
                let window_s = (f64::from(p.min_window_readings) - 1.0) / least_hz;
                c.fail(
                    "procedure.min_window_readings",
                    format!(
                        "expected at most {most} readings ({why} × procedure.ft_window_s {} s, + 1), found {}: lower it, or lengthen procedure.ft_window_s to {} s",
                        p.ft_window_s,
                        p.min_window_readings,
                        (window_s * 1000.0).ceil() / 1000.0
                    ),
                );
            }
        }
        c.within("procedure.ft_stale_s", p.ft_stale_s, 1e-3, 10.0, "s");
        // The approach guard calls the stream stale after ft_stale_s without a reading:
        // under three periods of the slowest rate, a healthy stream trips it.
        let stale_floor_s = 3.0 / least_hz;
        if least_hz.is_finite()
            && least_hz > 0.0
            && p.ft_stale_s.is_finite()
            && p.ft_stale_s < stale_floor_s
        {
            c.fail(
                "procedure.ft_stale_s",
                format!(
                    "expected at least three sensor periods ({why}: {} s), found {}: a healthy stream would stop every approach as stale",
                    (stale_floor_s * 1000.0).ceil() / 1000.0,
                    p.ft_stale_s
                ),
            );
        }
        if let Some(skew_s) = p.max_skew_s {
            let problems = c.problems().len();
            c.within(
                "procedure.max_skew_s",
                skew_s,
                1e-5,
                FT_BUFFER_S / 2.0,
                "s (half the force/torque buffer)",
            );
            // Readings 1/rate apart cover a frame between them within half a period
            // at best: a smaller limit would reject most frames.
            if c.problems().len() == problems
                && least_hz.is_finite()
                && least_hz > 0.0
                && skew_s * least_hz < 0.5
            {
                c.fail(
                    "procedure.max_skew_s",
                    format!(
                        "expected at least half a sensor period (0.5 / {why} = {} s), found {skew_s}",
                        0.5 / least_hz
                    ),
                );
            }
        }
        if p.max_attempts == 0 {
            c.fail("procedure.max_attempts", "expected at least 1 attempt");
        }
        if p.max_consecutive_failures == 0 {
            c.fail("procedure.max_consecutive_failures", "expected at least 1");
        }
    }
}

/// The most a sensor's configured latency may be, s: far beyond any real link, and a
/// bound that keeps stamps from being moved by seconds through a typo.
pub const MAX_SENSOR_LATENCY_S: f64 = 1.0;

pub(super) fn latency(c: &mut Check, field: &str, v: Option<f64>) {
    if let Some(v) = v {
        c.within(field, v, 0.0, MAX_SENSOR_LATENCY_S, "s");
    }
}

/// Exposure within 100 µs (one V4L2 step) and 1 s, white balance within the 1000 to
/// 15 000 K cameras offer.
fn image_settings(c: &mut Check, field: &str, image: Option<&super::ImageSettings>) {
    let Some(image) = image else { return };
    if let Some(us) = image.exposure_us {
        c.within(
            &format!("{field}.exposure_us"),
            f64::from(us),
            100.0,
            1e6,
            "µs",
        );
    }
    if let Some(k) = image.white_balance_k {
        c.within(
            &format!("{field}.white_balance_k"),
            f64::from(k),
            1000.0,
            15000.0,
            "K",
        );
    }
}

pub(super) fn non_empty(c: &mut Check, field: &str, v: &str) {
    if v.trim().is_empty() {
        c.fail(field, "expected a non-empty string");
    }
}
