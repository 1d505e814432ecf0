//! Synthetic samples and force/torque windows: `softtouch bench ingest`, the tests and
//! the examples (whose other fixtures are in `testing`, behind the `testing` feature).

use softtouch_schemas::{
    ContactPose, FtReading, FtStatus, Medium, Sample, SampleStatus, TimestampNs, Wrench,
};

/// Builds a [`Sample`]. [`SampleBuilder::new`] gives an accepted first-try sample of
/// `circle-10` in air at x = 10 mm, nothing measured: wrench (1, 2, 3 N, 0.1, 0.2,
/// 0.3 N·m) ± 0.01, 50 readings over 0–50 ms, the frame at 25 ms, no skew.
#[derive(Debug, Clone)]
pub struct SampleBuilder(Sample);

impl SampleBuilder {
    /// The default sample with this index.
    #[must_use]
    pub fn new(index: u64) -> Self {
        Self(Sample {
            index,
            rod: "circle-10".into(),
            medium: Medium::Air,
            commanded: ContactPose {
                x_m: 0.01,
                z_m: 0.0,
                theta_rad: 0.0,
            },
            measured: None,
            wrench_mean_in_sensor: Wrench::from_array([1.0, 2.0, 3.0, 0.1, 0.2, 0.3]),
            wrench_std_in_sensor: Wrench::from_array([0.01; 6]),
            reading_count: 50,
            frame_t: TimestampNs(25_000_000),
            window_start: TimestampNs(0),
            window_end: TimestampNs(50_000_000),
            sync_skew_ns: 0,
            status: SampleStatus::Ok,
            attempts: 1,
        })
    }

    /// The sample's index.
    #[must_use]
    pub const fn index(&self) -> u64 {
        self.0.index
    }

    #[must_use]
    pub fn rod(mut self, rod: &str) -> Self {
        rod.clone_into(&mut self.0.rod);
        self
    }

    #[must_use]
    pub const fn medium(mut self, medium: Medium) -> Self {
        self.0.medium = medium;
        self
    }

    /// The commanded pose.
    #[must_use]
    pub const fn pose(mut self, commanded: ContactPose) -> Self {
        self.0.commanded = commanded;
        self
    }

    /// The pose the arm reported.
    #[must_use]
    pub const fn measured(mut self, measured: ContactPose) -> Self {
        self.0.measured = Some(measured);
        self
    }

    /// The window's mean wrench (in the sensor frame).
    #[must_use]
    pub const fn wrench(mut self, mean: Wrench) -> Self {
        self.0.wrench_mean_in_sensor = mean;
        self
    }

    /// Readings in the window.
    #[must_use]
    pub const fn readings(mut self, count: u32) -> Self {
        self.0.reading_count = count;
        self
    }

    /// Frame time and window, ns.
    #[must_use]
    pub const fn times(mut self, frame_t: u64, window_start: u64, window_end: u64) -> Self {
        self.0.frame_t = TimestampNs(frame_t);
        self.0.window_start = TimestampNs(window_start);
        self.0.window_end = TimestampNs(window_end);
        self
    }

    #[must_use]
    pub const fn skew_ns(mut self, skew: i64) -> Self {
        self.0.sync_skew_ns = skew;
        self
    }

    #[must_use]
    pub const fn status(mut self, status: SampleStatus) -> Self {
        self.0.status = status;
        self
    }

    #[must_use]
    pub const fn attempts(mut self, attempts: u32) -> Self {
        self.0.attempts = attempts;
        self
    }

    /// The sample's window: `readings` of the mean wrench, evenly spaced from the
    /// window's start; sensor sequence numbers offset by `index % 1000`.
    #[must_use]
    pub fn window(&self) -> Vec<FtReading> {
        let s = &self.0;
        let count = s.reading_count;
        let step = (s.window_end.0.saturating_sub(s.window_start.0)) / u64::from(count.max(1));
        let offset = u32::try_from(s.index % 1000).unwrap_or(0);
        (0..count)
            .map(|k| FtReading {
                t: TimestampNs(s.window_start.0 + u64::from(k) * step),
                rdt_sequence: k,
                ft_sequence: k + offset,
                status: FtStatus::OK,
                wrench_in_sensor: s.wrench_mean_in_sensor,
            })
            .collect()
    }

    /// The sample.
    #[must_use]
    pub fn build(self) -> Sample {
        self.0
    }
}
