//! What the host offers a 1 kHz control loop: a real-time kernel, the SCHED_FIFO
//! priority and locked memory its user may take, and pinning a thread to one core.

use nix::sys::resource::{Resource, getrlimit};

/// The host's real-time facts, as `rig check` reports them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HostRealtime {
    /// `uname -r`.
    pub kernel_release: String,
    /// The kernel is PREEMPT_RT (`/sys/kernel/realtime` reads 1, or its version says
    /// so).
    pub preempt_rt: bool,
    /// The highest SCHED_FIFO priority this user may take (`ulimit -r`; `None`:
    /// unlimited).
    pub rtprio_limit: Option<u64>,
    /// Bytes this user may lock in memory (`ulimit -l`; `None`: unlimited).
    pub memlock_limit_bytes: Option<u64>,
}

impl HostRealtime {
    /// Why a real-time control loop cannot run here; empty when it can.
    #[must_use]
    pub fn problems(&self) -> Vec<String> {
        let mut p = Vec::new();
        if !self.preempt_rt {
            p.push(format!(
                "kernel {} is not PREEMPT_RT (install a real-time kernel, e.g. Debian's linux-image-rt-amd64)",
                self.kernel_release
            ));
        }
        if self.rtprio_limit == Some(0) {
            p.push(
                "this user may not take real-time priority (ulimit -r is 0: add rtprio 99 in /etc/security/limits.d)"
                    .to_owned(),
            );
        }
        p
    }
}

fn read_trimmed(path: &str) -> Option<String> {
    std::fs::read_to_string(path)
        .ok()
        .map(|s| s.trim().to_owned())
}

/// The soft limit of `r`; `None` when unlimited or unreadable as a number.
fn soft_limit(r: Resource) -> Option<u64> {
    match getrlimit(r) {
        Ok((soft, _)) if soft != nix::sys::resource::RLIM_INFINITY => Some(soft),
        _ => None,
    }
}

/// Reads the host's real-time facts (Linux `/proc`, `/sys` and rlimits).
#[must_use]
pub fn host_realtime() -> HostRealtime {
    let version = read_trimmed("/proc/sys/kernel/version").unwrap_or_default();
    let flag = read_trimmed("/sys/kernel/realtime").is_some_and(|s| s == "1");
    HostRealtime {
        kernel_release: read_trimmed("/proc/sys/kernel/osrelease")
            .unwrap_or_else(|| "unknown".into()),
        preempt_rt: flag || version.contains("PREEMPT_RT"),
        rtprio_limit: soft_limit(Resource::RLIMIT_RTPRIO),
        memlock_limit_bytes: soft_limit(Resource::RLIMIT_MEMLOCK),
    }
}

/// Pins the calling thread to the host's last core (the one the OS fills last), so
/// that the control loop does not migrate between cores. Returns the core.
///
/// # Errors
/// The scheduler refuses.
pub fn pin_to_last_core() -> Result<usize, String> {
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get);
    let core = cores - 1;
    let mut set = nix::sched::CpuSet::new();
    set.set(core).map_err(|e| e.to_string())?;
    nix::sched::sched_setaffinity(nix::unistd::Pid::from_raw(0), &set)
        .map_err(|e| format!("cannot pin to core {core}: {e}"))?;
    Ok(core)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_host_is_read_and_its_problems_named() {
        let h = host_realtime();
        assert!(!h.kernel_release.is_empty());
        let not_rt = HostRealtime {
            kernel_release: "6.1.0-13-amd64".into(),
            preempt_rt: false,
            rtprio_limit: Some(0),
            memlock_limit_bytes: Some(8 << 20),
        };
        let p = not_rt.problems();
        assert_eq!(p.len(), 2, "{p:?}");
        assert!(p[0].contains("6.1.0-13-amd64 is not PREEMPT_RT"));
        assert!(p[1].contains("ulimit -r is 0"));
        let rt = HostRealtime {
            preempt_rt: true,
            rtprio_limit: Some(99),
            ..not_rt
        };
        assert!(rt.problems().is_empty());
    }

    #[test]
    fn a_thread_can_be_pinned_to_the_last_core() {
        let core = std::thread::spawn(pin_to_last_core)
            .join()
            .expect("thread")
            .expect("pinned");
        let cores = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get);
        assert_eq!(core, cores - 1);
    }
}
