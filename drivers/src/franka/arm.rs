//! [`FrankaArm`], the handle: connects, starts the robot thread and implements [`Arm`]
//! over channels to it.

use super::*;

/// A Panda behind a worker thread. Implements [`Arm`].
#[derive(Debug)]
pub struct FrankaArm {
    tx: mpsc::Sender<Cmd>,
    cancel: Arc<Cancel>,
    /// The last move's generation (moves are numbered from 1).
    generation: u64,
    clock: Arc<dyn Clock>,
    feed: PoseFeed,
    /// The robot's mode at connect, and the recovery run if it needed one.
    found_at_connect: String,
}

impl FrankaArm {
    /// Connect (the FCI version the robot answers with; real time as the config says),
    /// set the end effector, payload and collision behaviour, and start the robot
    /// thread.
    pub async fn connect(config: FrankaConfig, clock: Arc<dyn Clock>) -> Result<Self, DeviceError> {
        if !(config.reflex_force_n.is_finite() && config.reflex_force_n > 0.0) {
            return Err(DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message: "reflex_force_n must be positive".into(),
            });
        }
        let (tx, rx) = mpsc::channel::<Cmd>();
        let (ready_tx, ready_rx) = oneshot::channel::<Result<String, DeviceError>>();
        let cancel = Arc::new(Cancel::default());
        let (cancel2, clock2) = (cancel.clone(), clock.clone());
        let (feed_tx, feed) = watch::channel(None);
        let feed_tx = Arc::new(feed_tx);
        std::thread::Builder::new()
            .name("franka".into())
            .spawn(move || {
                // One core for the 1 kHz loop: it does not migrate while the other
                // core decodes frames and encodes PNGs.
                match crate::realtime::pin_to_last_core() {
                    Ok(core) => tracing::info!("franka: control thread pinned to core {core}"),
                    Err(e) => tracing::warn!("franka: control thread not pinned: {e}"),
                }
                let realtime = match config.realtime {
                    softtouch_schemas::Realtime::Enforce => franka::RealtimeConfig::Enforce,
                    softtouch_schemas::Realtime::Ignore => {
                        tracing::warn!(
                            "franka: real time is not enforced (rig `realtime = \"ignore\"`): the 1 kHz loop will miss cycles under load and may end in communication_constraints_violation"
                        );
                        franka::RealtimeConfig::Ignore
                    }
                };
                // FCI v10 (FR3) first, then v5 (Panda) when the robot answers so.
                let options = franka::RobotOptions::new(realtime)
                    .with_version(franka::VersionPolicy::Auto);
                let robot = match franka::Robot::with_options(&config.address, options) {
                    Ok(r) => r,
                    Err(e) => {
                        let _ = ready_tx.send(Err(err(e)));
                        return;
                    }
                };
                // A robot left in reflex or with errors (a client that died mid-motion)
                // refuses every setting: recover it first, and say what was found.
                let found = match recover_first(&robot) {
                    Ok(found) => found,
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return;
                    }
                };
                // The robot's own Cartesian limits, by the FCI version it answered with.
                let kind = reach::Robot::of(robot.fci_version());
                let limits = config
                    .motion_margin
                    .map_or(config.limits, |m| MotionLimits::for_robot(kind, m));
                let set = configure(&robot, &config)
                    .and_then(|()| robot_kinematics(&robot))
                    .and_then(|(kin, q)| {
                        check_reach(&kin, kind, &q, &config, &limits)?;
                        Ok(kin)
                    });
                let kin = match set {
                    Ok(kin) => {
                        let _ = ready_tx.send(Ok(found));
                        kin
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return;
                    }
                };
                tracing::info!(
                    "franka: {} moves at {:.2} m/s, {:.1} m/s², {:.2} rad/s, {:.1} rad/s² at most",
                    kind.name(),
                    limits.max_speed_m_s,
                    limits.accel_m_s2,
                    limits.rot_speed_rad_s,
                    limits.rot_accel_rad_s2
                );
                worker(
                    robot,
                    rx,
                    limits,
                    Some((kin, kind)),
                    cancel2,
                    clock2,
                    feed_tx,
                );
            })
            .map_err(|e| DeviceError::Link {
                device: DEVICE.into(),
                message: format!("cannot start the robot thread: {e}"),
            })?;
        let found_at_connect = ready_rx.await.map_err(|_| gone())??;
        Ok(Self {
            tx,
            cancel,
            generation: 0,
            clock,
            feed,
            found_at_connect,
        })
    }

    async fn ask<T>(&self, make: impl FnOnce(Reply<T>) -> Cmd) -> Result<T, DeviceError> {
        let (reply, rx) = oneshot::channel();
        self.tx.send(make(reply)).map_err(|_| gone())?;
        rx.await.map_err(|_| gone())?
    }

    /// Send one motion through `legs` and wait for it; dropping the future cancels it.
    async fn move_path(
        &mut self,
        legs: Vec<(ArmPose, f64)>,
    ) -> Result<(ArmState, Vec<TimestampNs>), DeviceError> {
        if let Some((target, speed_m_s)) = legs.iter().find(|(target, speed_m_s)| {
            !(target.is_valid()
                && speed_m_s.is_finite()
                && *speed_m_s > 0.0
                && *speed_m_s <= MAX_SPEED_M_S)
        }) {
            return Err(DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message: format!(
                    "invalid target {target:?} or speed {speed_m_s} m/s (at most {MAX_SPEED_M_S})"
                ),
            });
        }
        self.generation += 1;
        let generation = self.generation;
        let (reply, rx) = oneshot::channel();
        self.tx
            .send(Cmd::Move {
                legs,
                generation,
                reply,
            })
            .map_err(|_| gone())?;
        let mut guard = CancelOnDrop {
            cancel: &self.cancel,
            generation,
            armed: true,
        };
        let r = rx.await.map_err(|_| gone())?;
        guard.armed = false;
        r
    }

    /// The clock the states are stamped with.
    #[must_use]
    pub fn clock(&self) -> &Arc<dyn Clock> {
        &self.clock
    }
}

#[async_trait]
impl Arm for FrankaArm {
    async fn move_to(&mut self, target: &ArmPose, speed_m_s: f64) -> Result<ArmState, DeviceError> {
        self.move_path(vec![(*target, speed_m_s)])
            .await
            .map(|(s, _)| s)
    }

    /// One motion where the legs lie along one straight line (it slows to a slower
    /// leg's speed before that leg and never stops between legs: [`super::blend`]);
    /// otherwise leg by leg.
    async fn move_through(
        &mut self,
        legs: &[(ArmPose, f64)],
    ) -> Result<(ArmState, Vec<TimestampNs>), DeviceError> {
        if legs.is_empty() {
            return self.state().await.map(|s| (s, Vec::new()));
        }
        self.move_path(legs.to_vec()).await
    }

    async fn state(&mut self) -> Result<ArmState, DeviceError> {
        self.ask(|reply| Cmd::State { reply }).await
    }

    async fn joints_rad(&mut self) -> Result<Option<[f64; 7]>, DeviceError> {
        self.ask(|reply| Cmd::Joints { reply }).await.map(Some)
    }

    async fn move_joints(&mut self, q_rad: &[f64; 7]) -> Result<Option<ArmState>, DeviceError> {
        if !q_rad.iter().all(|q| q.is_finite()) {
            return Err(DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message: format!("invalid joint target {q_rad:?}"),
            });
        }
        self.generation += 1;
        let generation = self.generation;
        let (reply, rx) = oneshot::channel();
        self.tx
            .send(Cmd::MoveJoints {
                q: *q_rad,
                generation,
                reply,
            })
            .map_err(|_| gone())?;
        let mut guard = CancelOnDrop {
            cancel: &self.cancel,
            generation,
            armed: true,
        };
        let r = rx.await.map_err(|_| gone())?;
        guard.armed = false;
        r.map(Some)
    }

    async fn recover(&mut self) -> Result<(), DeviceError> {
        self.ask(|reply| Cmd::Recover { reply }).await
    }

    async fn stop(&mut self) -> Result<(), DeviceError> {
        // Every move sent so far: the running one brakes, queued ones never start.
        self.cancel.cancel_through(self.generation);
        self.ask(|reply| Cmd::Stop { reply }).await
    }

    fn pose_feed(&self) -> Option<PoseFeed> {
        Some(self.feed.clone())
    }

    fn found_at_connect(&self) -> Option<String> {
        Some(self.found_at_connect.clone())
    }
}

/// Read the robot's mode before any setting; one in reflex or with errors (its client
/// died mid-motion, or an aborted motion was never recovered) refuses every setting,
/// so the automatic error recovery runs first (logged). What was found, for `rig
/// check` and the collection's log.
fn recover_first(robot: &franka::Robot) -> Result<String, DeviceError> {
    let s = robot.read_once().map_err(err)?;
    let mode = s.robot_mode;
    let errors = s.current_errors.any();
    if !(mode == franka::RobotMode::Reflex || errors) {
        return Ok(format!("{mode:?}"));
    }
    let what = format!("{mode:?}{}", if errors { " with errors" } else { "" });
    tracing::warn!(
        "franka: the robot was in {what} at connect: running the automatic error recovery before any setting"
    );
    robot.automatic_error_recovery().map_err(|e| match err(e) {
        DeviceError::Fault { device, code, message } => DeviceError::Fault {
            device,
            code,
            message: format!(
                "the robot was in {what} at connect and its automatic error recovery failed: {message}; recover it in Desk"
            ),
        },
        other => other,
    })?;
    let after = robot.read_once().map_err(err)?;
    Ok(format!(
        "{what}; automatic error recovery run, now {:?}",
        after.robot_mode
    ))
}

/// Cancels its move if the move's future is dropped before it completes.
struct CancelOnDrop<'a> {
    cancel: &'a Cancel,
    generation: u64,
    armed: bool,
}

impl Drop for CancelOnDrop<'_> {
    fn drop(&mut self) {
        if self.armed {
            self.cancel.cancel_through(self.generation);
        }
    }
}
