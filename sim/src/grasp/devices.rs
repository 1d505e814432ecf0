//! The soft grasp's gripper and finger cameras behind the drivers' Gripper and Camera traits.

use super::*;

#[async_trait]
impl Gripper for SoftGripper {
    async fn activate(&mut self) -> Result<(), DeviceError> {
        let activated = lock_state(&self.state)?.activated;
        if !activated {
            tokio::time::sleep(crate::gripper::ACTIVATION).await;
            let now = self.clock.now();
            let mut s = lock_state(&self.state)?;
            s.advance(now).map_err(|e| device_fault(GRIPPER, &e))?;
            s.activated = true;
        }
        Ok(())
    }

    async fn command(&mut self, cmd: GripperCommand) -> Result<(), DeviceError> {
        let now = self.clock.now();
        let mut s = lock_state(&self.state)?;
        if !s.activated {
            return Err(DeviceError::InvalidCommand {
                device: GRIPPER.into(),
                message: "not activated".into(),
            });
        }
        s.advance(now).map_err(|e| device_fault(GRIPPER, &e))?;
        s.cmd = cmd;
        Ok(())
    }

    async fn status(&mut self) -> Result<GripperStatus, DeviceError> {
        let now = self.clock.now();
        let mut s = lock_state(&self.state)?;
        s.advance(now).map_err(|e| device_fault(GRIPPER, &e))?;
        let current_ma = match s.status {
            ObjectStatus::ContactClosing | ObjectStatus::ContactOpening => {
                (100.0 + 500.0 * f64::from(s.cmd.force) / 255.0) as u32
            }
            ObjectStatus::Moving => 150,
            ObjectStatus::AtPosition => 0,
        };
        Ok(GripperStatus {
            t: now,
            activated: s.activated,
            object: s.status,
            fault: 0,
            requested_position: s.cmd.position,
            position: position_for_opening(s.opening_mm),
            current_ma,
        })
    }
}

#[async_trait]
impl Camera for SoftFingerCamera {
    async fn frame_after(&mut self, t: TimestampNs, timeout_ms: u64) -> Result<Frame, DeviceError> {
        let k = (t.0 as f64 / self.period_ns).ceil() as u64;
        self.frame_k(k, t, timeout_ms).await
    }

    /// The frame exposed last before now when it is not older than `t` (a loop that
    /// fell behind skips to it), else the first at or after `t`.
    async fn latest_frame_after(
        &mut self,
        t: TimestampNs,
        timeout_ms: u64,
    ) -> Result<Frame, DeviceError> {
        let first = (t.0 as f64 / self.period_ns).ceil() as u64;
        let mut newest = (self.clock.now().0 as f64 / self.period_ns).floor() as u64;
        // Rounding of the frame times: the newest is the last one at or before now.
        while newest > 0 && self.frame_time(newest) > self.clock.now() {
            newest -= 1;
        }
        self.frame_k(first.max(newest), t, timeout_ms).await
    }

    fn dropped_frames(&self) -> u64 {
        0
    }
}

impl SoftFingerCamera {
    fn frame_time(&self, k: u64) -> TimestampNs {
        TimestampNs((k as f64 * self.period_ns).round() as u64)
    }

    /// Frame `k`, waited for; a timeout when it comes more than `timeout_ms` after `t`.
    async fn frame_k(
        &mut self,
        k: u64,
        t: TimestampNs,
        timeout_ms: u64,
    ) -> Result<Frame, DeviceError> {
        let exposed = TimestampNs((k as f64 * self.period_ns).round() as u64);
        if exposed.0.saturating_sub(t.0) > timeout_ms.saturating_mul(1_000_000) {
            tokio::time::sleep_until(self.clock.instant_at(TimestampNs(
                t.0.saturating_add(timeout_ms.saturating_mul(1_000_000)),
            )))
            .await;
            return Err(DeviceError::Timeout {
                device: CAMERA.into(),
                timeout_ms,
            });
        }
        tokio::time::sleep_until(self.clock.instant_at(exposed)).await;
        let mut s = lock_state(&self.state)?;
        // The frame's buffers on the second core while this one works out the
        // finger's contact and lattice.
        let background = s.scene(self.finger).background();
        let mut buffers = None;
        let mut look = None;
        crate::second_core::join(
            || look = Some(self.look_at(&mut s, exposed)),
            || buffers = Some(FrameBuffers::new(&background)),
        );
        let look = match look {
            Some(look) => look?,
            None => self.look_at(&mut s, exposed)?,
        };
        let scene = s.scene(self.finger);
        let data = scene.render_into(&look, k, exposed.0 as f64 * 1e-9, buffers);
        Ok(Frame {
            meta: FrameMeta {
                t: exposed,
                sequence: k,
                width: crate::WIDTH,
                height: crate::HEIGHT,
                format: FrameFormat::Rgb8,
            },
            data,
        })
    }
}
