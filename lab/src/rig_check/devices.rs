//! Each device's check: what is exercised and measured, and what makes it fail.

use super::*;

/// How far the arm check moves the finger, m (up, along the base's z), and how slowly.
const ARM_CHECK_STEP_M: f64 = 0.001;
const ARM_CHECK_SPEED_M_S: f64 = 0.005;
/// Least share of real-time commands that must reach the robot during the check move.
const MIN_COMMAND_SUCCESS_RATE: f64 = 0.95;
/// How far from a target a move may end and still count as reached, m.
const ARM_CHECK_TOLERANCE_M: f64 = 0.0005;

pub(super) async fn check_arm(
    mut arm: Box<dyn Arm>,
    workspace: &softtouch_schemas::rig::WorkspaceBounds,
) -> Result<ArmCheck, String> {
    let s = arm
        .state()
        .await
        .map_err(|e| format!("expected a state read: {e}"))?;
    let p = s.base_from_finger;
    if !p.is_valid() {
        return Err(format!(
            "expected a finite pose with a unit quaternion, read {p:?}"
        ));
    }
    if s.faulted {
        return Err(format!(
            "expected no fault: the arm reports a reflex/error state at {:?} m; recover it first",
            p.translation_m
        ));
    }
    // A state read passes an arm that cannot move (stopped by the user, braked, FCI
    // not granted): a millimetre up and back shows that it can.
    let mut up = p;
    up.translation_m[2] += ARM_CHECK_STEP_M;
    if !workspace.contains_arm(&up) {
        return Err(format!(
            "expected room to move {} mm up inside workspace.reach_in_base_m from {:?} m; move the arm into the workspace first",
            ARM_CHECK_STEP_M * 1000.0,
            p.translation_m
        ));
    }
    let mut worst_m: f64 = 0.0;
    // The real-time link's health, as each move's state reports it: sampled while the
    // move ran (libfranka's rate reads 0 when no motion runs); the worse of the two.
    let mut command_success_rate: Option<f64> = None;
    for (what, target) in [("up", up), ("back", p)] {
        let reached = arm.move_to(&target, ARM_CHECK_SPEED_M_S).await.map_err(|e| {
            format!(
                "expected the arm to move {} mm {what} (is it in a mode that can move: FCI granted, not stopped by the user?): {e}",
                ARM_CHECK_STEP_M * 1000.0
            )
        });
        let reached = match reached {
            Ok(r) => r,
            Err(e) => {
                let _ = arm.stop().await;
                return Err(e);
            }
        };
        let off_m = reached.base_from_finger.distance_to(&target);
        // NaN (a pose that does not read) fails too.
        if off_m.is_nan() || off_m > ARM_CHECK_TOLERANCE_M {
            return Err(format!(
                "expected the move {what} to end within {} mm of its target, ended {:.3} mm away",
                ARM_CHECK_TOLERANCE_M * 1000.0,
                off_m * 1000.0
            ));
        }
        worst_m = worst_m.max(off_m);
        if let Some(rate) = reached.command_success_rate {
            command_success_rate =
                Some(softtouch_drivers::franka::lower(command_success_rate, rate));
        }
    }
    // A host that misses cycles fails here before it fails a night.
    if let Some(rate) = command_success_rate
        && (rate.is_nan() || rate < MIN_COMMAND_SUCCESS_RATE)
    {
        return Err(format!(
            "expected at least {:.0} % of the real-time commands to reach the robot during the move, {:.1} % did: the host misses cycles (real-time kernel and priority, docs/RIG.md; a direct cable to the control box)",
            MIN_COMMAND_SUCCESS_RATE * 100.0,
            rate * 100.0
        ));
    }
    Ok(ArmCheck {
        translation_m: p.translation_m,
        moved_mm: ARM_CHECK_STEP_M * 1000.0,
        worst_arrival_mm: worst_m * 1000.0,
        command_success_rate,
        found_at_connect: arm.found_at_connect(),
    })
}

pub(super) async fn check_force_sensor(
    mut sensor: Box<dyn ForceSensor>,
    rate_hz: f64,
    window: Duration,
    clock: &dyn Clock,
) -> Result<StreamCheck, String> {
    sensor
        .start()
        .await
        .map_err(|e| format!("expected the stream to start: {e}"))?;
    let result = read_window(sensor.as_mut(), rate_hz, window, clock).await;
    // Stop the stream whatever the result; the reading's outcome is the one to report.
    let _ = sensor.stop().await;
    result
}

pub(super) async fn read_window(
    sensor: &mut dyn ForceSensor,
    rate_hz: f64,
    window: Duration,
    clock: &dyn Clock,
) -> Result<StreamCheck, String> {
    let mut readings = Vec::new();
    // The first read waits for the stream; the window starts at its first reading.
    sensor
        .read(&mut readings)
        .await
        .map_err(|e| format!("expected readings at {rate_hz} Hz: {e}"))?;
    readings.clear();
    let lost_before = sensor.lost_readings();
    let start = clock.now();
    let window_ns = u64::try_from(window.as_nanos()).unwrap_or(u64::MAX);
    while clock.now().0.saturating_sub(start.0) < window_ns {
        sensor
            .read(&mut readings)
            .await
            .map_err(|e| format!("expected readings at {rate_hz} Hz: {e}"))?;
    }
    let elapsed_s = clock.now().0.saturating_sub(start.0) as f64 * 1e-9;
    // What the sensor sent, on the host's clock: readings lost on the way count (a
    // lossy link is not a slow sensor; `lost` says so separately).
    let sent = readings.len() as u64 + sensor.lost_readings().saturating_sub(lost_before);
    let measured_hz = sent as f64 / elapsed_s.max(1e-9);
    let faults = readings
        .iter()
        .filter(|r| !r.status.is_ok() && !r.status.is_warning())
        .count();
    let warnings = readings.iter().filter(|r| r.status.is_warning()).count();
    let non_finite = readings
        .iter()
        .filter(|r| !r.wrench_in_sensor.is_finite())
        .count();
    let lost = sensor.lost_readings();
    let mean_fz = readings
        .iter()
        .map(|r| r.wrench_in_sensor.force_n[2])
        .sum::<f64>()
        / readings.len().max(1) as f64;
    let stream = StreamCheck {
        readings: readings.len(),
        elapsed_s,
        measured_hz,
        rate_hz,
        lost,
        warnings,
        mean_fz_n: mean_fz,
    };
    let summary = stream.to_string();
    check_stream_rate(measured_hz, rate_hz).map_err(|e| format!("{summary}; {e}"))?;
    if faults > 0 {
        let first = readings
            .iter()
            .find(|r| !r.status.is_ok() && !r.status.is_warning())
            .map(|r| r.status.to_string())
            .unwrap_or_default();
        return Err(format!(
            "{summary}; expected no faulted status word, {faults} had one (first {first})"
        ));
    }
    if non_finite > 0 {
        return Err(format!(
            "{summary}; expected finite values, {non_finite} readings had NaN/∞"
        ));
    }
    Ok(stream)
}

/// Whether a stream measured at `measured_hz` is the configured `rate_hz`: its period
/// within [`RATE_REFUSED`] of the configured one either way, the tolerance the Net F/T
/// driver refuses a stream past once it runs (one number: a sensor this check passes
/// is not refused in the night). Readings are stamped from their sequence at the
/// configured period, so a sensor at 875 Hz configured as 1000 Hz would have its
/// stamps run early by 125 ms for every second of stream: refused, naming both rates.
pub(super) fn check_stream_rate(measured_hz: f64, rate_hz: f64) -> Result<(), String> {
    // As the driver judges it: the configured period against the measured one.
    let off = rate_hz / measured_hz - 1.0;
    if off.abs() <= RATE_REFUSED {
        return Ok(());
    }
    Err(format!(
        "expected the configured {rate_hz:.0} Hz within {:.0} %, the sensor sent {measured_hz:.0} Hz: readings are stamped from their sequence at the configured period, so set force_sensor.rate_hz to the rate the sensor streams at (Net F/T: its web page's RDT output rate)",
        RATE_REFUSED * 100.0
    ))
}

pub(super) async fn check_camera(
    mut camera: Box<dyn Camera>,
    clock: &dyn Clock,
) -> Result<FrameCheck, String> {
    let frame = camera
        .frame_after(clock.now(), 2000)
        .await
        .map_err(|e| format!("expected a frame within 2 s: {e}"))?;
    let m = &frame.meta;
    if m.width == 0 || m.height == 0 {
        return Err(format!(
            "expected a non-empty frame, got {}×{}",
            m.width, m.height
        ));
    }
    if m.format == FrameFormat::Rgb8 {
        let want = m.width as usize * m.height as usize * 3;
        if frame.data.len() != want {
            return Err(format!(
                "expected {want} bytes of RGB8 for {}×{}, got {}",
                m.width,
                m.height,
                frame.data.len()
            ));
        }
    } else if frame.data.is_empty() {
        return Err(format!("expected {:?} bytes, got none", m.format));
    }
    Ok(FrameCheck {
        sequence: m.sequence,
        width: m.width,
        height: m.height,
        format: m.format,
        bytes: frame.data.len(),
        dropped: camera.dropped_frames(),
        settings: camera.settings(),
    })
}

/// Sends `position` and waits (re-sending within the keep-alive) until the echo and
/// arrival or a contact stop.
pub(super) async fn move_gripper(
    gripper: &mut dyn Gripper,
    clock: &dyn Clock,
    position: u8,
) -> Result<softtouch_drivers::GripperStatus, String> {
    let cmd = GripperCommand {
        position,
        speed: 128,
        force: 20,
    };
    let fail = |e: DeviceError| format!("expected the move to count {position}: {e}");
    gripper.command(cmd).await.map_err(fail)?;
    let start = clock.now();
    let mut sent = start;
    loop {
        tokio::time::sleep(Duration::from_millis(10)).await;
        let s = gripper.status().await.map_err(fail)?;
        if s.fault != 0 {
            return Err(format!(
                "expected no fault while moving to count {position}: {}",
                softtouch_drivers::hande::regs::describe_fault(s.fault)
            ));
        }
        if s.requested_position == position && s.object != ObjectStatus::Moving {
            return Ok(s);
        }
        let now = clock.now();
        if now.0.saturating_sub(sent.0) >= 200_000_000 {
            gripper.command(cmd).await.map_err(fail)?;
            sent = now;
        }
        if now.0.saturating_sub(start.0) > 3_000_000_000 {
            return Err(format!(
                "expected the fingers at count {position} within 3 s, they are at {} (gPR echo {}, gOBJ {:?})",
                s.position, s.requested_position, s.object
            ));
        }
    }
}

pub(super) async fn check_gripper(
    mut gripper: Box<dyn Gripper>,
    clock: &dyn Clock,
    latency_timer_ms: Option<u32>,
) -> Result<GripperCheck, String> {
    gripper
        .activate()
        .await
        .map_err(|e| format!("expected activation: {e}"))?;
    let before = gripper
        .status()
        .await
        .map_err(|e| format!("expected a status read: {e}"))?;
    if !before.activated {
        return Err("expected gSTA = 3 (activated) after activation".into());
    }
    if before.fault != 0 {
        return Err(format!(
            "expected no fault after activation: {}",
            softtouch_drivers::hande::regs::describe_fault(before.fault)
        ));
    }
    // A small move towards the middle of the scale and back.
    let start = before.position;
    let target = if start < 128 {
        start.saturating_add(GRIPPER_TEST_COUNTS)
    } else {
        start.saturating_sub(GRIPPER_TEST_COUNTS)
    };
    let there = move_gripper(gripper.as_mut(), clock, target).await?;
    let back = move_gripper(gripper.as_mut(), clock, start).await?;
    let moved = i32::from(there.position) - i32::from(start);
    if moved.unsigned_abs() < u32::from(GRIPPER_TEST_COUNTS) / 2 {
        return Err(format!(
            "expected the fingers to move about {GRIPPER_TEST_COUNTS} counts from {start} to {target}, they reached {} (gOBJ {:?})",
            there.position, there.object
        ));
    }
    let exchanges_hz = time_exchanges(gripper.as_mut(), clock, back.position).await?;
    if let Some(ms) = latency_timer_ms.filter(|&ms| ms > MAX_LATENCY_TIMER_MS) {
        return Err(format!(
            "expected the USB-serial adapter's latency timer at {MAX_LATENCY_TIMER_MS} ms, it is {ms} ms: every reply waits that long{}. Set it to 1 ms (docs/RIG.md, \"The FTDI latency timer\")",
            exchanges_hz.map_or_else(String::new, |hz| format!(
                " (measured: {hz:.0} exchanges/s)"
            ))
        ));
    }
    Ok(GripperCheck {
        start,
        reached: there.position,
        back: back.position,
        object: back.object,
        current_ma: back.current_ma,
        exchanges_hz,
        latency_timer_ms,
    })
}

/// Times [`LINK_TEST_EXCHANGES`] move-and-status exchanges that hold the fingers at
/// `position`: the rate a loop of one exchange a cycle could reach on this link.
async fn time_exchanges(
    gripper: &mut dyn Gripper,
    clock: &dyn Clock,
    position: u8,
) -> Result<Option<f64>, String> {
    let hold = GripperCommand {
        position,
        speed: 128,
        force: 20,
    };
    let start = clock.now();
    for _ in 0..LINK_TEST_EXCHANGES {
        let s = gripper
            .command_and_status(hold)
            .await
            .map_err(|e| format!("expected move-and-status exchanges: {e}"))?;
        if s.fault != 0 {
            return Err(format!(
                "expected no fault while holding: {}",
                softtouch_drivers::hande::regs::describe_fault(s.fault)
            ));
        }
    }
    let elapsed_s = clock.now().0.saturating_sub(start.0) as f64 * 1e-9;
    Ok((elapsed_s > 0.0).then(|| f64::from(LINK_TEST_EXCHANGES) / elapsed_s))
}

#[cfg(test)]
mod tests {
    use super::*;
    use softtouch_drivers::ArmState;
    use softtouch_schemas::{ArmPose, TimestampNs};

    /// An arm that reads fine and moves as told: `off_m` from each target, or not at
    /// all (`refuse`, as one stopped by the user).
    struct Stub {
        at: ArmPose,
        off_m: f64,
        refuse: bool,
        /// The command success rate it reports with a move's state, sampled while the
        /// move ran; a state read between moves reports 0, as libfranka documents.
        rate: Option<f64>,
    }

    fn state(p: ArmPose) -> ArmState {
        ArmState {
            t: TimestampNs(0),
            base_from_finger: p,
            external_wrench: None,
            faulted: false,
            command_success_rate: None,
        }
    }

    #[async_trait::async_trait]
    impl Arm for Stub {
        async fn move_to(&mut self, target: &ArmPose, _: f64) -> Result<ArmState, DeviceError> {
            if self.refuse {
                return Err(DeviceError::Fault {
                    device: "arm".into(),
                    code: None,
                    message: "user stopped".into(),
                });
            }
            self.at = *target;
            self.at.translation_m[0] += self.off_m;
            Ok(ArmState {
                command_success_rate: self.rate,
                ..state(self.at)
            })
        }
        async fn state(&mut self) -> Result<ArmState, DeviceError> {
            Ok(ArmState {
                command_success_rate: self.rate.map(|_| 0.0),
                ..state(self.at)
            })
        }
        async fn recover(&mut self) -> Result<(), DeviceError> {
            Ok(())
        }
        async fn stop(&mut self) -> Result<(), DeviceError> {
            Ok(())
        }
    }

    fn run(stub: Stub) -> Result<ArmCheck, String> {
        let rig = softtouch_schemas::defaults::rig();
        let rt = tokio::runtime::Builder::new_current_thread()
            .build()
            .expect("runtime");
        rt.block_on(check_arm(Box::new(stub), &rig.workspace))
    }

    fn home() -> ArmPose {
        let w = softtouch_schemas::defaults::rig().workspace;
        ArmPose::from_contact(&w.base_from_rod, &w.home)
    }

    #[test]
    fn an_arm_passes_only_when_it_moves_a_millimetre_and_back() {
        let ok = run(Stub {
            at: home(),
            off_m: 0.0001,
            refuse: false,
            rate: None,
        })
        .expect("moves");
        assert!((ok.moved_mm - 1.0).abs() < 1e-12);
        assert!((ok.worst_arrival_mm - 0.1).abs() < 1e-9);
        let e = run(Stub {
            at: home(),
            off_m: 0.0,
            refuse: true,
            rate: None,
        })
        .expect_err("a user-stopped arm fails");
        assert!(
            e.contains("in a mode that can move") && e.contains("user stopped"),
            "{e}"
        );
        let e = run(Stub {
            at: home(),
            off_m: 0.002,
            refuse: false,
            rate: None,
        })
        .expect_err("an arm that ends 2 mm off fails");
        assert!(e.contains("ended 2.000 mm away"), "{e}");
        let mut outside = home();
        outside.translation_m[2] = 10.0;
        let e = run(Stub {
            at: outside,
            off_m: 0.0,
            refuse: false,
            rate: None,
        })
        .expect_err("no room to move");
        assert!(e.contains("expected room to move 1 mm up"), "{e}");
        // A Panda whose host missed cycles during the move.
        let ok = run(Stub {
            at: home(),
            off_m: 0.0,
            refuse: false,
            rate: Some(0.99),
        })
        .expect("99 % arrived");
        assert!(
            Measured::Arm(ok)
                .to_string()
                .contains("99.0 % of real-time commands")
        );
        for bad in [0.9, f64::NAN] {
            let e = run(Stub {
                at: home(),
                off_m: 0.0,
                refuse: false,
                rate: Some(bad),
            })
            .expect_err("missed cycles");
            assert!(e.contains("the host misses cycles"), "{e}");
        }
    }

    /// A sensor that sends one reading every `period` (on a fixed schedule: the paused
    /// clock's timer rounds each sleep to the millisecond), and loses every
    /// `lose_every`th.
    struct Paced {
        period: Duration,
        next: Option<tokio::time::Instant>,
        lose_every: u32,
        sent: u32,
        lost: u64,
        clock: TokioClock,
    }

    #[async_trait::async_trait]
    impl ForceSensor for Paced {
        async fn start(&mut self) -> Result<(), DeviceError> {
            Ok(())
        }
        async fn read(
            &mut self,
            out: &mut Vec<softtouch_schemas::FtReading>,
        ) -> Result<usize, DeviceError> {
            let mut n = 0;
            while n == 0 {
                let next = *self
                    .next
                    .get_or_insert_with(|| tokio::time::Instant::now() + self.period);
                tokio::time::sleep_until(next).await;
                let now = tokio::time::Instant::now();
                while self.next.is_some_and(|t| t <= now) {
                    self.next = self.next.map(|t| t + self.period);
                    self.sent += 1;
                    if self.lose_every > 0 && self.sent.is_multiple_of(self.lose_every) {
                        self.lost += 1;
                        continue;
                    }
                    out.push(softtouch_schemas::FtReading {
                        t: self.clock.now(),
                        rdt_sequence: self.sent,
                        ft_sequence: self.sent,
                        status: softtouch_schemas::FtStatus::OK,
                        wrench_in_sensor: softtouch_schemas::Wrench::default(),
                    });
                    n += 1;
                }
            }
            Ok(n)
        }
        async fn bias(&mut self) -> Result<(), DeviceError> {
            Ok(())
        }
        async fn stop(&mut self) -> Result<(), DeviceError> {
            Ok(())
        }
        fn lost_readings(&self) -> u64 {
            self.lost
        }
    }

    async fn stream_at(hz: f64, lose_every: u32) -> Result<StreamCheck, String> {
        let clock = TokioClock::new();
        let mut s = Paced {
            period: Duration::from_secs_f64(1.0 / hz),
            next: None,
            lose_every,
            sent: 0,
            lost: 0,
            clock,
        };
        read_window(&mut s, 1000.0, Duration::from_secs(1), &clock).await
    }

    #[tokio::test(start_paused = true)]
    async fn a_stream_at_another_rate_than_configured_is_refused_by_both_rates() {
        let ok = stream_at(1000.0, 0).await.expect("1000 Hz as configured");
        assert!((ok.measured_hz - 1000.0).abs() < 5.0, "{ok:?}");
        // 875 Hz against 1000 Hz: passed before (above 80 %); the stamps would run
        // 125 ms early per second of stream.
        let e = stream_at(875.0, 0).await.expect_err("875 Hz");
        assert!(
            e.contains("1000 Hz within 5 %") && e.contains("sent 875 Hz"),
            "{e}"
        );
        // 5-10 % off passed here before and was refused by the driver in the night.
        let e = stream_at(930.0, 0).await.expect_err("930 Hz");
        assert!(e.contains("sent 930 Hz"), "{e}");
        stream_at(960.0, 0)
            .await
            .expect("960 Hz: within the driver's 5 %");
        let e = stream_at(1200.0, 0)
            .await
            .expect_err("faster than configured");
        assert!(e.contains("sent 1200 Hz"), "{e}");
        // A lossy link at the right rate is not a slow sensor.
        let lossy = stream_at(1000.0, 10).await.expect("10 % lost");
        assert!(lossy.lost > 50, "{lossy:?}");
        assert!(check_stream_rate(f64::NAN, 1000.0).is_err());
    }

    /// The simulator's Hand-E behind its Modbus register map, over an in-memory pipe:
    /// the exchanges are real function-23 transactions.
    async fn gripper_check(latency_timer_ms: Option<u32>) -> Result<GripperCheck, String> {
        let clock = TokioClock::new();
        let rig = SimRig::new(
            &softtouch_schemas::defaults::rig(),
            &softtouch_schemas::defaults::scene(),
            3,
            clock,
        )
        .expect("sim rig");
        let service = softtouch_drivers::hande::HandEService::new(rig.gripper, 9);
        let (a, b) = tokio::io::duplex(1024);
        tokio::spawn(softtouch_drivers::hande::serve_rtu(
            service,
            b,
            std::future::pending(),
        ));
        let hand_e = softtouch_drivers::hande::HandE::new(
            a,
            softtouch_drivers::hande::HandEConfig::default(),
            Arc::new(clock),
        );
        check_gripper(Box::new(hand_e), &clock, latency_timer_ms).await
    }

    #[tokio::test(start_paused = true)]
    async fn the_gripper_check_times_the_link_and_refuses_a_slow_adapter() {
        let ok = gripper_check(Some(1)).await.expect("passes at 1 ms");
        // Paced at the Hand-E's 200 transactions a second, on the paused clock.
        let hz = ok.exchanges_hz.expect("time passed");
        assert!((150.0..=200.0).contains(&hz), "{hz}");
        assert_eq!(ok.latency_timer_ms, Some(1));
        assert!(Measured::Gripper(ok).to_string().contains("exchanges/s"));
        let e = gripper_check(Some(16)).await.expect_err("16 ms fails");
        assert!(
            e.contains("latency timer at 1 ms, it is 16 ms") && e.contains("docs/RIG.md"),
            "{e}"
        );
        assert!(
            gripper_check(None).await.is_ok(),
            "no adapter: nothing to check"
        );
    }
}
