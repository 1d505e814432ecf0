//! What the host offers a 1 kHz control loop: a real-time kernel, the SCHED_FIFO
//! priority and locked memory its user may take, and pinning a thread to one core.
//!
//! Judged as franka-rs judges at connect (`realtime = "enforce"`): the kernel is
//! real-time only if `/sys/kernel/realtime` reads 1 (a version string that says
//! PREEMPT_RT is not enough), and the control thread asks for SCHED_FIFO at priority
//! 99, the highest, so `ulimit -r` must be 99 unless the process may raise its own
//! priority (`CAP_SYS_NICE`, as root has).

use nix::sys::resource::{Resource, getrlimit};

/// The host's real-time facts, as `rig check` reports them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HostRealtime {
    /// `uname -r`.
    pub kernel_release: String,
    /// The kernel is PREEMPT_RT as franka-rs reads it: `/sys/kernel/realtime` reads 1.
    pub preempt_rt: bool,
    /// The kernel's version string says PREEMPT_RT (`uname -v`).
    pub version_says_preempt_rt: bool,
    /// The process may raise its own scheduling priority whatever `ulimit -r` says
    /// (`CAP_SYS_NICE` in its effective capabilities).
    pub cap_sys_nice: bool,
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
        if !self.preempt_rt && self.version_says_preempt_rt {
            p.push(format!(
                "kernel {}'s version says PREEMPT_RT but /sys/kernel/realtime does not read 1, and that file is what the Franka connection checks (boot a kernel built with CONFIG_PREEMPT_RT, e.g. Debian's linux-image-rt-amd64)",
                self.kernel_release
            ));
        } else if !self.preempt_rt {
            p.push(format!(
                "kernel {} is not PREEMPT_RT (/sys/kernel/realtime does not read 1: install a real-time kernel, e.g. Debian's linux-image-rt-amd64)",
                self.kernel_release
            ));
        }
        if let Some(limit) = self.rtprio_limit
            && limit < FRANKA_PRIORITY
            && !self.cap_sys_nice
        {
            p.push(format!(
                "this user may take real-time priority up to {limit} (ulimit -r) and the Franka control thread asks for {FRANKA_PRIORITY}: add `@realtime - rtprio 99` to /etc/security/limits.d/99-realtime.conf, add the user to the realtime group (usermod -aG realtime $USER) and log in again"
            ));
        }
        p
    }
}

/// The SCHED_FIFO priority franka-rs gives the control thread (the highest).
pub const FRANKA_PRIORITY: u64 = 99;

/// What to change when the Franka connection is refused for real time: libfranka's
/// own text says only what failed.
pub const REFUSED_ADVICE: &str = "the 1 kHz loop needs a PREEMPT_RT kernel (/sys/kernel/realtime reads 1) and SCHED_FIFO priority 99 for this user (`@realtime - rtprio 99` in /etc/security/limits.d/99-realtime.conf, the user in that group, a new login); `softtouch rig check` names what is missing. For a first look only, set `realtime = \"ignore\"` in the rig's [arm] table (docs/RIG.md)";

/// Whether the effective capabilities in `/proc/self/status`'s `CapEff` line hold
/// `CAP_SYS_NICE` (bit 23).
#[must_use]
pub fn cap_sys_nice_in(status: &str) -> bool {
    const CAP_SYS_NICE: u32 = 23;
    status
        .lines()
        .find_map(|l| l.strip_prefix("CapEff:"))
        .and_then(|v| u64::from_str_radix(v.trim(), 16).ok())
        .is_some_and(|caps| caps & (1 << CAP_SYS_NICE) != 0)
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
        preempt_rt: flag,
        version_says_preempt_rt: version.contains("PREEMPT_RT"),
        cap_sys_nice: read_trimmed("/proc/self/status").is_some_and(|s| cap_sys_nice_in(&s)),
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
            version_says_preempt_rt: false,
            cap_sys_nice: false,
            rtprio_limit: Some(0),
            memlock_limit_bytes: Some(8 << 20),
        };
        let p = not_rt.problems();
        assert_eq!(p.len(), 2, "{p:?}");
        assert!(p[0].contains("6.1.0-13-amd64 is not PREEMPT_RT"));
        assert!(p[1].contains("up to 0 (ulimit -r)") && p[1].contains("limits.d"));
        let rt = HostRealtime {
            preempt_rt: true,
            rtprio_limit: Some(99),
            ..not_rt.clone()
        };
        assert!(rt.problems().is_empty());
        // franka-rs asks for priority 99: a limit of 50 is refused at connect.
        let p = HostRealtime {
            rtprio_limit: Some(50),
            ..rt.clone()
        }
        .problems();
        assert_eq!(p.len(), 1, "{p:?}");
        assert!(
            p[0].contains("up to 50") && p[0].contains("asks for 99"),
            "{p:?}"
        );
        // ... unless the process may raise its own priority (root).
        let root = HostRealtime {
            rtprio_limit: Some(0),
            cap_sys_nice: true,
            ..rt.clone()
        };
        assert!(root.problems().is_empty());
        // A version string that says PREEMPT_RT without /sys/kernel/realtime is not
        // what franka-rs accepts.
        let p = HostRealtime {
            preempt_rt: false,
            version_says_preempt_rt: true,
            ..rt
        }
        .problems();
        assert_eq!(p.len(), 1, "{p:?}");
        assert!(
            p[0].contains("/sys/kernel/realtime does not read 1"),
            "{p:?}"
        );
    }

    #[test]
    fn cap_sys_nice_is_read_from_the_effective_capabilities() {
        let root = "Name:\tx\nCapPrm:\t000001ffffffffff\nCapEff:\t000001ffffffffff\n";
        assert!(cap_sys_nice_in(root));
        let user = "CapPrm:\t0000000000800000\nCapEff:\t0000000000000000\n";
        assert!(!cap_sys_nice_in(user));
        assert!(cap_sys_nice_in("CapEff:\t0000000000800000"));
        for bad in [
            "",
            "CapEff:",
            "CapEff:\tzz",
            "CapEff:\t1ffffffffffffffffffff",
        ] {
            assert!(!cap_sys_nice_in(bad), "{bad:?}");
        }
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
