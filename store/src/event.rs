//! What an event is about: the `kind` column of the events table.

use softtouch_schemas::sample::RejectReason;
use std::fmt;

/// The kind of an event, stored as [`EventKind::as_str`]. Queries and reports match on
/// these strings, so a variant's text never changes once stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventKind {
    /// A run was resumed.
    Resumed,
    /// A rod was put in place.
    RodChange,
    /// An arm reflex or other recoverable arm fault.
    ArmFault,
    /// Automatic recovery after an arm fault succeeded.
    ArmRecovered,
    /// A stop command to the arm failed: it may still be moving.
    ArmStopFailed,
    /// A window was refused; stored under the reason's own name.
    WindowRejected(RejectReason),
    /// The force guard aborted an approach.
    ForceLimit,
    /// No frame came in time.
    FrameTimeout,
    /// The force/torque sensor failed while recording.
    SensorFault,
    /// A forced stop interrupted a sample.
    Interrupted,
    /// A sample was stored as rejected once its attempts ran out.
    Rejected,
    /// The arm could not retreat home at the end of a run.
    RetreatFailed,
    /// Reading, loss and drop counts of the streams at the end of a run.
    StreamCounts,
    /// The force/torque sensor did not stop cleanly.
    SensorStop,
    /// Every planned sample is stored.
    Completed,
    /// The operator stopped the run.
    Stopped,
    /// The run stopped safely after faults.
    SafeStop,
    /// The approach guard stopped the arm: the stream went stale, failed, or sent a
    /// non-finite reading.
    GuardStop,
    /// The run's lease was taken over from a process that is gone.
    LeaseTakenOver,
    /// The devices could not be set up or started: nothing was collected.
    StartFailed,
    /// The order a rod's block of samples is visited in (its fingerprint).
    VisitPlan,
    /// Where the samples' time went: per phase, over the samples of a job.
    PhaseTimes,
    /// The elbow's drift over a block (a robot arm's joints against home's), and its
    /// move back in joint space.
    Elbow,
}

impl EventKind {
    /// As stored.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Resumed => "resumed",
            Self::RodChange => "rod_change",
            Self::ArmFault => "arm_fault",
            Self::ArmRecovered => "arm_recovered",
            Self::ArmStopFailed => "arm_stop_failed",
            Self::WindowRejected(reason) => reason.as_str(),
            Self::ForceLimit => "force_limit",
            Self::FrameTimeout => "frame_timeout",
            Self::SensorFault => "sensor_fault",
            Self::Interrupted => "interrupted",
            Self::Rejected => "rejected",
            Self::RetreatFailed => "retreat_failed",
            Self::StreamCounts => "stream_counts",
            Self::SensorStop => "sensor_stop",
            Self::Completed => "completed",
            Self::Stopped => "stopped",
            Self::SafeStop => "safe_stop",
            Self::GuardStop => "guard_stop",
            Self::LeaseTakenOver => "lease_taken_over",
            Self::StartFailed => "start_failed",
            Self::VisitPlan => "visit_plan",
            Self::PhaseTimes => "phase_times",
            Self::Elbow => "elbow",
        }
    }
}

impl fmt::Display for EventKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stored_kinds_are_unchanged() {
        // Existing databases and the tests' queries use these strings.
        assert_eq!(EventKind::ArmFault.as_str(), "arm_fault");
        assert_eq!(EventKind::ArmRecovered.as_str(), "arm_recovered");
        assert_eq!(EventKind::StreamCounts.as_str(), "stream_counts");
        assert_eq!(
            EventKind::WindowRejected(RejectReason::ShortWindow).as_str(),
            "short_window"
        );
        assert_eq!(EventKind::SafeStop.to_string(), "safe_stop");
    }
}
