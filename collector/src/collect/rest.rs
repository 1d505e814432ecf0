//! The finger's rest frames, taken once at a run's start with the arm at home (no
//! contact) and stored with the run: what an image tare for another medium is fitted
//! against (`softtouch transfer --tare`), with no label of that medium.

use super::*;

/// Rest frames a run keeps: their mean cancels the camera's noise (σ/√8).
pub const REST_FRAMES: usize = 8;

/// Time between rest frames, s: 8 of them span 3.5 s, so light that moves across
/// the finger (underwater caustics, bubbles) is averaged over its course instead of
/// caught at one place. Eight frames in a row (1/120 s apart on the default rig) saw
/// one pattern of the shipped water's caustics (a 2 s cycle), which the tare then
/// took for the finger's colour: a land model read water at R² 0.647 through that
/// tare and 0.934 through one fitted on frames without the caustics
/// (docs/land-to-water.md).
pub const REST_SPACING_S: f64 = 0.5;

/// [`REST_FRAMES`] frames of `camera`, the first at or after `start`, each
/// [`REST_SPACING_S`] after the one before: the one way rest frames are taken, for a
/// run and for a grasp scene's tare alike.
///
/// # Errors
/// The camera's, for the first frame it does not give.
pub async fn rest_frames<C: softtouch_drivers::Camera + ?Sized>(
    camera: &mut C,
    start: softtouch_schemas::TimestampNs,
    timeout_ms: u64,
) -> Result<Vec<softtouch_drivers::Frame>, softtouch_drivers::DeviceError> {
    let mut frames: Vec<softtouch_drivers::Frame> = Vec::with_capacity(REST_FRAMES);
    for _ in 0..REST_FRAMES {
        let after = frames.last().map_or(start, |f| {
            f.meta
                .t
                .saturating_add(softtouch_schemas::DurationNs::from_secs_f64(REST_SPACING_S))
        });
        frames.push(camera.frame_after(after, timeout_ms).await?);
    }
    Ok(frames)
}

impl Job<'_> {
    /// Takes the [`rest_frames`] and stores them with the run (a resumed run keeps
    /// those of its first start). A camera that does not answer is logged (a warning:
    /// the samples need no rest frame, only a tare of this run does) and the run goes
    /// on; a store that fails stops it.
    pub(super) async fn take_rest_frames(&mut self) -> Result<(), CollectError> {
        let timeout_ms = (self.plan.rig.procedure.frame_timeout_s * 1000.0).ceil() as u64;
        let start = self.clock.now();
        let frames = match rest_frames(&mut *self.camera, start, timeout_ms).await {
            Ok(frames) => frames,
            Err(e) => {
                self.events.log(
                    EventKind::FrameTimeout,
                    EventLevel::Warn,
                    None,
                    &format!(
                        "no rest frame from the camera at home ({e}): the run goes on without them (`transfer --tare` cannot use it)"
                    ),
                )?;
                return Ok(());
            }
        };
        let encoded = frames
            .iter()
            .map(crate::store::encode_for_store)
            .collect::<Result<Vec<_>, _>>()?;
        self.store.insert_rest_frames(self.plan.run_id, encoded)?;
        Ok(())
    }
}
