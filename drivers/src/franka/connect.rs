//! Connecting: [`FrankaConfig`], what connect sets on the robot before any motion, and
//! the checks of what the robot reports back (end effector, payload, stiffness frame,
//! collision thresholds, the route from where the arm is).

use super::*;

/// Connection settings.
#[derive(Debug, Clone, PartialEq)]
pub struct FrankaConfig {
    /// The robot's address (`172.16.0.2`, optionally `:port`).
    pub address: String,
    /// Upper force threshold of the collision behaviour, N (half of it the lower one).
    pub reflex_force_n: f64,
    /// Upper Cartesian torque threshold, N·m (half of it the lower one).
    pub reflex_torque_nm: f64,
    /// Whether real-time scheduling is required.
    pub realtime: softtouch_schemas::Realtime,
    /// `NE_T_EE` for `set_ee`, column-major; `None` leaves Desk's end effector.
    pub ne_t_ee: Option<[f64; 16]>,
    /// The payload for `set_load`: mass (kg), centre of mass in the flange frame (m),
    /// inertia (kg·m²); `None` sets none.
    pub payload: Option<(f64, [f64; 3], [f64; 9])>,
    /// Upper joint torque thresholds of the collision behaviour, N·m (half of each
    /// the lower one); each below the joint's torque limit.
    pub joint_torque_thresholds_nm: [f64; 7],
    /// Move limits.
    pub limits: MotionLimits,
    /// The route to check against the robot's joint ranges and velocity limits at
    /// connect, from the joints the arm is at ([`reach`]); empty: none.
    pub route: Vec<reach::Leg>,
    /// `Some(m)`: at connect, `limits` become `m` of the Cartesian limits of the robot
    /// the FCI version names ([`MotionLimits::for_robot`]); `None`: `limits` as given.
    pub motion_margin: Option<f64>,
}

impl FrankaConfig {
    /// The settings a rig's `franka` table gives.
    #[must_use]
    pub fn from_rig(d: &softtouch_schemas::ArmDevice) -> Option<Self> {
        let softtouch_schemas::ArmDevice::Franka {
            address,
            reflex_force_n,
            reflex_torque_nm,
            realtime,
            end_effector,
            payload,
            joint_torque_thresholds_nm,
            motion_margin,
        } = d
        else {
            return None;
        };
        Some(Self {
            address: address.clone(),
            reflex_force_n: *reflex_force_n,
            reflex_torque_nm: reflex_torque_nm.unwrap_or(0.1 * reflex_force_n),
            realtime: *realtime,
            ne_t_ee: end_effector.as_deref().map(|p| p.normalised().to_matrix()),
            payload: payload
                .as_deref()
                .map(|p| (p.mass_kg, p.com_in_flange_m, p.inertia_kg_m2)),
            joint_torque_thresholds_nm: joint_torque_thresholds_nm
                .unwrap_or(softtouch_schemas::FRANKA_DEFAULT_JOINT_TORQUE_THRESHOLDS_NM),
            limits: MotionLimits::default(),
            route: Vec::new(),
            motion_margin: Some(
                motion_margin.unwrap_or(softtouch_schemas::FRANKA_DEFAULT_MOTION_MARGIN),
            ),
        })
    }

    /// The settings of a rig's arm, with its workspace's route to check at connect
    /// (home, each corner and back, at the procedure's speeds).
    #[must_use]
    pub fn for_rig(rig: &softtouch_schemas::RigConfig) -> Option<Self> {
        let mut c = Self::from_rig(&rig.arm)?;
        c.route = reach::workspace_route(
            &rig.workspace,
            rig.procedure.approach_speed_m_s,
            rig.procedure.retreat_speed_m_s,
        );
        Some(c)
    }
}

/// Whether the robot holds the end effector and payload it was given: what a state
/// read reports beside what was set (`NE_T_EE`, the load's mass and centre of mass).
/// A robot that accepted `set_ee` but reports another frame would put every commanded
/// pose off by the difference.
pub fn check_configured(
    config: &FrankaConfig,
    ne_t_ee: &[f64; 16],
    m_load: f64,
    f_x_cload: &[f64; 3],
) -> Result<(), String> {
    const TOL: f64 = 1e-6;
    let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= TOL);
    if let Some(want) = &config.ne_t_ee
        && !close(want, ne_t_ee)
    {
        return Err(format!(
            "set_ee was sent but the robot reports NE_T_EE translation ({:.4}, {:.4}, {:.4}) m, expected ({:.4}, {:.4}, {:.4}) m",
            ne_t_ee[12], ne_t_ee[13], ne_t_ee[14], want[12], want[13], want[14]
        ));
    }
    if let Some((mass, com, _)) = &config.payload
        && !((m_load - mass).abs() <= TOL && close(com, f_x_cload))
    {
        return Err(format!(
            "set_load was sent but the robot reports a load of {m_load} kg at {f_x_cload:?} m, expected {mass} kg at {com:?} m"
        ));
    }
    Ok(())
}

/// What connect sets before any motion: the end effector, the payload, the collision
/// thresholds (in that order: the thresholds act on the estimate the other two shape);
/// then the end effector and payload are read back.
pub(super) fn configure(robot: &franka::Robot, config: &FrankaConfig) -> Result<(), DeviceError> {
    if let Some(ne_t_ee) = config.ne_t_ee {
        robot.set_ee(ne_t_ee).map_err(err)?;
    }
    if let Some((mass, com, inertia)) = config.payload {
        robot.set_load(mass, com, inertia).map_err(err)?;
    }
    if config.ne_t_ee.is_some() || config.payload.is_some() {
        let s = robot.read_once().map_err(err)?;
        check_configured(config, &s.NE_T_EE, s.m_load, &s.F_x_Cload).map_err(|message| {
            DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message,
            }
        })?;
    }
    // The stiffness frame at the end effector: the external wrench the guard can
    // cross-check is then the finger's, not wherever Desk left K.
    robot.set_k(IDENTITY).map_err(err)?;
    let s = robot.read_once().map_err(err)?;
    check_stiffness_frame(&s.EE_T_K).map_err(|message| DeviceError::InvalidCommand {
        device: DEVICE.into(),
        message,
    })?;
    let (upper_q, lower_q) =
        joint_thresholds(&config.joint_torque_thresholds_nm).map_err(|message| {
            DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message,
            }
        })?;
    let (f, t) = (config.reflex_force_n, config.reflex_torque_nm);
    let lower_f = [f * 0.5, f * 0.5, f * 0.5, t * 0.5, t * 0.5, t * 0.5];
    let upper_f = [f, f, f, t, t, t];
    robot
        .set_collision_behavior_simple(lower_q, upper_q, lower_f, upper_f)
        .map_err(err)
}

/// The arm's kinematics with its end effector as the robot reports it: its `O_T_EE`
/// against the model's flange at its joints. On a robot this is `F_T_EE`; a simulator
/// whose reported frame is not the documented flange (franka-sim's link7, TESTING.md)
/// is taken at its word.
pub(super) fn robot_kinematics(
    robot: &franka::Robot,
) -> Result<(reach::Kinematics, [f64; 7]), DeviceError> {
    let s = robot.read_once().map_err(err)?;
    let kin = reach::Kinematics::new(IDENTITY);
    let flange = kin.pose(&s.q);
    let reported = ArmPose::from_matrix(&s.O_T_EE);
    let f_t_ee = flange.inverse().compose(&reported);
    let told = ArmPose::from_matrix(&s.F_T_EE);
    if f_t_ee.distance_to(&told) > 1e-3 || f_t_ee.angle_to(&told) > 0.01 {
        tracing::warn!(
            "franka: the robot's O_T_EE is {:.1} mm and {:.2} rad from its model's flange · F_T_EE: the reach and joint speed checks take the pose it reports",
            f_t_ee.distance_to(&told) * 1000.0,
            f_t_ee.angle_to(&told)
        );
    }
    Ok((kin.with_end_effector(f_t_ee.to_matrix()), s.q))
}

/// The route of `config` from the joints `q` the arm is at, against the limits of
/// `kind`; refused before any motion.
pub(super) fn check_reach(
    kin: &reach::Kinematics,
    kind: reach::Robot,
    q: &[f64; 7],
    config: &FrankaConfig,
    limits: &MotionLimits,
) -> Result<(), DeviceError> {
    if config.route.is_empty() {
        return Ok(());
    }
    reach::check_route(kin, kind, q, &config.route, limits.rot_speed_rad_s)
        .map(|_| ())
        .map_err(|e| DeviceError::InvalidCommand {
            device: DEVICE.into(),
            message: format!(
                "the rig's workspace is beyond the {}'s limits from its joints now, refused before any motion: {e}",
                kind.name()
            ),
        })
}

/// Whether the robot reports the stiffness frame at the end effector (`EE_T_K` the
/// identity), as connect set it.
pub fn check_stiffness_frame(ee_t_k: &[f64; 16]) -> Result<(), String> {
    if ee_t_k
        .iter()
        .zip(IDENTITY)
        .all(|(a, b)| (a - b).abs() <= 1e-6)
    {
        Ok(())
    } else {
        Err(format!(
            "set_k sent the identity but the robot reports EE_T_K translation ({:.4}, {:.4}, {:.4}) m: the external wrench would not be the finger's",
            ee_t_k[12], ee_t_k[13], ee_t_k[14]
        ))
    }
}

/// The collision behaviour's joint torque thresholds, `(upper, lower)` N·m: the
/// configured upper ones (each above 0 and below the joint's torque limit, else the
/// joint reflex could never act) and half of each as the lower.
pub fn joint_thresholds(upper_nm: &[f64; 7]) -> Result<([f64; 7], [f64; 7]), String> {
    softtouch_schemas::rig::check_joint_thresholds(upper_nm)?;
    Ok((*upper_nm, upper_nm.map(|v| 0.5 * v)))
}
