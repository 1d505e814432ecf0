//! Each device's check: what is exercised and measured, and what makes it fail.

use super::*;

pub(super) async fn check_arm(mut arm: Box<dyn Arm>) -> Result<ArmCheck, String> {
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
    Ok(ArmCheck {
        translation_m: p.translation_m,
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
    Ok(stream)
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

pub(super) async fn check_gripper(
    mut gripper: Box<dyn Gripper>,
    clock: &dyn Clock,
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
    Ok(GripperCheck {
        start,
        reached: there.position,
        back: back.position,
        object: back.object,
        current_ma: back.current_ma,
    })
}
