//! `softtouch rig check`: briefly exercise every device the rig config names and
//! print a pass/fail table (exit 0 only when every row passes).
//!
//! Each device is opened and checked on its own, so one dead device fails its row and
//! the others are still checked: the arm's state (pose, fault flag), the force/torque
//! stream (rate over a short window against the configured rate, status words,
//! finite values), a frame from each finger camera (size, format, byte count), and
//! the gripper (activation, a small close and open with the gPR echo, status). A
//! simulated device is the simulator's twin of the real one; with every device
//! simulated the check runs on tokio's paused clock and takes no real time.

use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::anyhow;
use clap::{Args, Subcommand};
use softtouch_drivers::open::{real_arm, real_camera, real_force_sensor, real_gripper};
use softtouch_drivers::{
    Arm, Camera, Clock, DeviceError, ForceSensor, Gripper, GripperCommand, ObjectStatus, TokioClock,
};
use softtouch_schemas::rig::{ArmDevice, CameraDevice, ForceSensorDevice, GripperDevice};
use softtouch_schemas::{FrameFormat, RigConfig};
use softtouch_sim::SimRig;

use super::{Failure, io_failure};

/// Rig verbs.
#[derive(Debug, Subcommand)]
pub enum RigCommand {
    /// Exercise every configured device briefly: arm state, force/torque stream rate and
    /// status, a frame from each camera, gripper activation with a small close/open.
    /// Prints a pass/fail table; exit 0 only if every device passes, 1 otherwise.
    #[command(after_help = "Examples:
  softtouch rig check                      # the embedded all-simulated rig
  softtouch rig check --rig lab.toml --window-s 1")]
    Check(CheckArgs),
}

/// Options of `rig check`.
#[derive(Debug, Args)]
pub struct CheckArgs {
    /// Rig file; default: the embedded all-simulated rig.
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Scene file for the simulated devices; default: the built-in scene.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// How long the force/torque stream is read, s.
    #[arg(long, default_value_t = 0.5)]
    pub window_s: f64,
    /// Longest time one device's check may take (opening included), s.
    #[arg(long, default_value_t = 5.0)]
    pub timeout_s: f64,
}

/// One row of the table.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CheckRow {
    /// Which device (`arm`, `force_sensor`, `camera`, `second_camera`, `gripper`).
    pub device: &'static str,
    /// Its driver.
    pub driver: String,
    /// Passed.
    pub pass: bool,
    /// What was measured, or what was expected and what happened.
    pub detail: String,
}

/// Least measured rate of the force/torque stream, as a fraction of the configured one.
const MIN_RATE_FRACTION: f64 = 0.8;
/// Counts of the gripper's test move.
const GRIPPER_TEST_COUNTS: u8 = 20;

/// Run a rig verb.
pub async fn run(cmd: RigCommand, out: &mut dyn Write) -> Result<(), Failure> {
    match cmd {
        RigCommand::Check(args) => check_verb(args, out).await,
    }
}

async fn check_verb(args: CheckArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let bad = |m: String| Failure::BadInput(anyhow!(m));
    if !(args.window_s.is_finite() && args.window_s > 0.0 && args.window_s <= 60.0) {
        return Err(bad(format!(
            "--window-s {}: expected a time in (0, 60] s",
            args.window_s
        )));
    }
    if !(args.timeout_s.is_finite() && args.timeout_s > 0.0 && args.timeout_s <= 600.0) {
        return Err(bad(format!(
            "--timeout-s {}: expected a time in (0, 600] s",
            args.timeout_s
        )));
    }
    if args.timeout_s <= args.window_s {
        return Err(bad(format!(
            "--timeout-s {} must exceed --window-s {} (the stream is read for the window)",
            args.timeout_s, args.window_s
        )));
    }
    let resolved = crate::configs::resolve(args.rig.as_deref(), args.scene.as_deref())?;
    let rows = check_rig(
        &resolved.rig,
        &resolved.scene,
        Duration::from_secs_f64(args.window_s),
        Duration::from_secs_f64(args.timeout_s),
    )
    .await;
    print_rows(&rows, out)?;
    let failed = rows.iter().filter(|r| !r.pass).count();
    if failed == 0 {
        Ok(())
    } else {
        Err(Failure::Runtime(anyhow!(
            "rig check: {failed} of {} devices failed",
            rows.len()
        )))
    }
}

fn print_rows(rows: &[CheckRow], out: &mut dyn Write) -> Result<(), Failure> {
    writeln!(
        out,
        "{:<14} {:<11} {:<6} detail",
        "device", "driver", "result"
    )
    .map_err(io_failure)?;
    for r in rows {
        writeln!(
            out,
            "{:<14} {:<11} {:<6} {}",
            r.device,
            r.driver,
            if r.pass { "pass" } else { "FAIL" },
            r.detail
        )
        .map_err(io_failure)?;
    }
    Ok(())
}

fn all_simulated(rig: &RigConfig) -> bool {
    matches!(rig.arm, ArmDevice::Sim { .. })
        && matches!(rig.force_sensor, ForceSensorDevice::Sim { .. })
        && matches!(rig.camera, CameraDevice::Sim { .. })
        && matches!(rig.second_camera, None | Some(CameraDevice::Sim { .. }))
        && matches!(rig.gripper, GripperDevice::Sim {})
}

/// The rig with every real device replaced by its simulated twin.
fn simulated_twin(rig: &RigConfig) -> RigConfig {
    let mut r = rig.clone();
    if let ArmDevice::Franka { reflex_force_n, .. } = r.arm {
        r.arm = ArmDevice::Sim { reflex_force_n };
    }
    r.force_sensor = ForceSensorDevice::Sim {
        rate_hz: rig.force_sensor.rate_hz(),
    };
    if let CameraDevice::V4l { .. } = r.camera {
        r.camera = CameraDevice::Sim { fps: 120.0 };
    }
    r.second_camera = None;
    r.gripper = GripperDevice::Sim {};
    r
}

fn where_arm(d: &ArmDevice) -> String {
    match d {
        ArmDevice::Sim { .. } => "the simulator".into(),
        ArmDevice::Franka { address, .. } => address.clone(),
    }
}

fn where_sensor(d: &ForceSensorDevice) -> String {
    match d {
        ForceSensorDevice::Sim { .. } => "the simulator".into(),
        ForceSensorDevice::NetFt { address, .. } => format!(
            "{address} (Net F/T: RDT over UDP, calibration over TCP unless counts_per_force and counts_per_torque are given)"
        ),
        ForceSensorDevice::AtiSerial { port, baud, .. } => format!("{port} at {baud} baud"),
    }
}

fn where_camera(d: &CameraDevice) -> String {
    match d {
        CameraDevice::Sim { .. } => "the simulator".into(),
        CameraDevice::V4l { device, .. } => device.clone(),
    }
}

fn where_gripper(d: &GripperDevice) -> String {
    match d {
        GripperDevice::Sim {} => "the simulator".into(),
        GripperDevice::HandE { port, slave_id } => {
            format!("{port}, Modbus RTU slave {slave_id} at 115200 baud")
        }
    }
}

fn driver_of_arm(d: &ArmDevice) -> &'static str {
    match d {
        ArmDevice::Sim { .. } => "sim",
        ArmDevice::Franka { .. } => "franka",
    }
}

fn driver_of_sensor(d: &ForceSensorDevice) -> &'static str {
    match d {
        ForceSensorDevice::Sim { .. } => "sim",
        ForceSensorDevice::NetFt { .. } => "net-ft",
        ForceSensorDevice::AtiSerial { .. } => "ati-serial",
    }
}

fn driver_of_camera(d: &CameraDevice) -> &'static str {
    match d {
        CameraDevice::Sim { .. } => "sim",
        CameraDevice::V4l { .. } => "v4l",
    }
}

fn driver_of_gripper(d: &GripperDevice) -> &'static str {
    match d {
        GripperDevice::Sim {} => "sim",
        GripperDevice::HandE { .. } => "hand-e",
    }
}

/// Runs `check` under `timeout`; a timeout or an error fails the row.
async fn row<F>(device: &'static str, driver: &str, timeout: Duration, check: F) -> CheckRow
where
    F: std::future::Future<Output = Result<String, String>>,
{
    let (pass, detail) = match tokio::time::timeout(timeout, check).await {
        Ok(Ok(detail)) => (true, detail),
        Ok(Err(why)) => (false, why),
        Err(_) => (
            false,
            format!(
                "expected the check to finish within {:.1} s (--timeout-s); the device did not answer in time",
                timeout.as_secs_f64()
            ),
        ),
    };
    CheckRow {
        device,
        driver: driver.to_owned(),
        pass,
        detail,
    }
}

/// Checks every device of `rig`; simulated ones run on the simulator built from
/// `scene`. Never fails as a whole: every problem is a failed row.
pub async fn check_rig(
    rig: &RigConfig,
    scene: &softtouch_schemas::SceneSpec,
    window: Duration,
    timeout: Duration,
) -> Vec<CheckRow> {
    if all_simulated(rig) {
        tokio::time::pause();
    }
    let clock = TokioClock::new();
    let shared: Arc<dyn Clock> = Arc::new(clock);
    let mut rows = Vec::new();
    let sim = match SimRig::new(&simulated_twin(rig), scene, 0, clock) {
        Ok(s) => Some(s),
        Err(e) => {
            rows.push(CheckRow {
                device: "simulator",
                driver: "sim".into(),
                pass: false,
                detail: format!("the simulated devices cannot be built: {e}"),
            });
            None
        }
    };
    let (mut sim_arm, mut sim_sensor, mut sim_camera, mut sim_gripper, handle) = match sim {
        Some(s) => (
            Some(s.arm),
            Some(s.force_sensor),
            Some(s.camera),
            Some(s.gripper),
            Some(s.handle),
        ),
        None => (None, None, None, None, None),
    };
    let no_sim = || "the simulator is not available (see the simulator row)".to_owned();

    rows.push(
        row("arm", driver_of_arm(&rig.arm), timeout, async {
            let arm: Box<dyn Arm> = match real_arm(&rig.arm, shared.clone()).await.map_err(|e| {
                format!("expected the arm answering at {}: {e}", where_arm(&rig.arm))
            })? {
                Some(a) => a,
                None => Box::new(sim_arm.take().ok_or_else(no_sim)?),
            };
            check_arm(arm).await
        })
        .await,
    );
    rows.push(
        row(
            "force_sensor",
            driver_of_sensor(&rig.force_sensor),
            timeout,
            async {
                let sensor: Box<dyn ForceSensor> =
                    match real_force_sensor(&rig.force_sensor, shared.clone())
                        .await
                        .map_err(|e| {
                            format!(
                                "expected the sensor answering at {}: {e}",
                                where_sensor(&rig.force_sensor)
                            )
                        })? {
                        Some(s) => s,
                        None => Box::new(sim_sensor.take().ok_or_else(no_sim)?),
                    };
                check_force_sensor(sensor, rig.force_sensor.rate_hz(), window, &*shared).await
            },
        )
        .await,
    );
    rows.push(
        row("camera", driver_of_camera(&rig.camera), timeout, async {
            let camera: Box<dyn Camera> = match real_camera(&rig.camera, shared.clone())
                .await
                .map_err(|e| format!("expected a camera at {}: {e}", where_camera(&rig.camera)))?
            {
                Some(c) => c,
                None => Box::new(sim_camera.take().ok_or_else(no_sim)?),
            };
            check_camera(camera, &*shared).await
        })
        .await,
    );
    if let Some(second) = &rig.second_camera {
        rows.push(
            row("second_camera", driver_of_camera(second), timeout, async {
                let camera: Box<dyn Camera> = match real_camera(second, shared.clone())
                    .await
                    .map_err(|e| format!("expected a camera at {}: {e}", where_camera(second)))?
                {
                    Some(c) => c,
                    // The rod-press simulator has one finger camera; its twin stands in.
                    None => Box::new(
                        SimRig::new(&simulated_twin(rig), scene, 1, clock)
                            .map_err(|e| format!("simulated camera: {e}"))?
                            .camera,
                    ),
                };
                check_camera(camera, &*shared).await
            })
            .await,
        );
    }
    rows.push(
        row("gripper", driver_of_gripper(&rig.gripper), timeout, async {
            let gripper: Box<dyn Gripper> = match real_gripper(&rig.gripper, shared.clone())
                .await
                .map_err(|e| {
                format!("expected a gripper at {}: {e}", where_gripper(&rig.gripper))
            })? {
                Some(g) => g,
                None => Box::new(sim_gripper.take().ok_or_else(no_sim)?),
            };
            check_gripper(gripper, &*shared).await
        })
        .await,
    );
    drop(handle);
    rows
}

async fn check_arm(mut arm: Box<dyn Arm>) -> Result<String, String> {
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
    let [x, y, z] = p.translation_m;
    Ok(format!(
        "pose ({x:.3}, {y:.3}, {z:.3}) m in the base frame, no fault"
    ))
}

async fn check_force_sensor(
    mut sensor: Box<dyn ForceSensor>,
    rate_hz: f64,
    window: Duration,
    clock: &dyn Clock,
) -> Result<String, String> {
    sensor
        .start()
        .await
        .map_err(|e| format!("expected the stream to start: {e}"))?;
    let result = read_window(sensor.as_mut(), rate_hz, window, clock).await;
    // Stop the stream whatever the result; the reading's outcome is the one to report.
    let _ = sensor.stop().await;
    result
}

async fn read_window(
    sensor: &mut dyn ForceSensor,
    rate_hz: f64,
    window: Duration,
    clock: &dyn Clock,
) -> Result<String, String> {
    let mut readings = Vec::new();
    // The first read waits for the stream; the window starts at its first reading.
    sensor
        .read(&mut readings)
        .await
        .map_err(|e| format!("expected readings at {rate_hz} Hz: {e}"))?;
    readings.clear();
    let start = clock.now();
    let window_ns = u64::try_from(window.as_nanos()).unwrap_or(u64::MAX);
    while clock.now().0.saturating_sub(start.0) < window_ns {
        sensor
            .read(&mut readings)
            .await
            .map_err(|e| format!("expected readings at {rate_hz} Hz: {e}"))?;
    }
    let elapsed_s = clock.now().0.saturating_sub(start.0) as f64 * 1e-9;
    let measured_hz = readings.len() as f64 / elapsed_s.max(1e-9);
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
    let summary = format!(
        "{} readings in {elapsed_s:.2} s: {measured_hz:.0} Hz of {rate_hz:.0} Hz configured, {lost} lost, {warnings} warnings, mean Fz {mean_fz:.3} N",
        readings.len()
    );
    if measured_hz < MIN_RATE_FRACTION * rate_hz {
        return Err(format!(
            "{summary}; expected at least {:.0} Hz ({:.0}% of the configured rate)",
            MIN_RATE_FRACTION * rate_hz,
            MIN_RATE_FRACTION * 100.0
        ));
    }
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
    Ok(summary)
}

async fn check_camera(mut camera: Box<dyn Camera>, clock: &dyn Clock) -> Result<String, String> {
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
    Ok(format!(
        "frame {} {}×{} {:?}, {} bytes, {} dropped",
        m.sequence,
        m.width,
        m.height,
        m.format,
        frame.data.len(),
        camera.dropped_frames()
    ))
}

/// Sends `position` and waits (re-sending within the keep-alive) until the echo and
/// arrival or a contact stop.
async fn move_gripper(
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
                "expected no fault while moving to count {position}: gFLT 0x{:02X}",
                s.fault
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

async fn check_gripper(mut gripper: Box<dyn Gripper>, clock: &dyn Clock) -> Result<String, String> {
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
            "expected no fault after activation: gFLT 0x{:02X}",
            before.fault
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
    Ok(format!(
        "activated; moved {start} → {} → {} counts, gOBJ {:?}, current {} mA, no fault",
        there.position, back.position, back.object, back.current_ma
    ))
}
