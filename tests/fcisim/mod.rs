//! franka-sim (PyPI), an independent FCI server, started for one test: MuJoCo's FR3 on
//! loopback, a free port, both enforcement options on (motion limits and
//! communication constraints abort a motion as a robot does).
//!
//! Needs `SOFTTOUCH_FRANKA_SIM_PYTHON`: a Python with franka-sim installed (`.ci/run`
//! makes one; TESTING.md says how by hand). Without it the tier is skipped with a
//! message, except under CI, where it fails.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The repository root (the CLI crate's parent).
pub(crate) fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap_or(Path::new("."))
        .to_owned()
}

/// The Python that runs franka-sim, or `None` (skip) outside CI.
pub(crate) fn python() -> Option<PathBuf> {
    match std::env::var_os("SOFTTOUCH_FRANKA_SIM_PYTHON") {
        Some(p) if !p.is_empty() => Some(PathBuf::from(p)),
        _ => {
            let ci = std::env::var("CI")
                .is_ok_and(|v| !v.is_empty() && v != "0" && !v.eq_ignore_ascii_case("false"));
            assert!(
                !ci,
                "SOFTTOUCH_FRANKA_SIM_PYTHON is not set: under CI the franka-sim tier must run (.ci/run installs it)"
            );
            eprintln!(
                "skipped: set SOFTTOUCH_FRANKA_SIM_PYTHON to a Python with franka-sim (TESTING.md, the franka-sim tier)"
            );
            None
        }
    }
}

/// A running franka-sim; killed when dropped.
#[derive(Debug)]
pub(crate) struct FrankaSim {
    child: Option<Child>,
    /// Its FCI command port on 127.0.0.1.
    pub(crate) port: u16,
    /// Its log (stderr).
    pub(crate) log: PathBuf,
}

impl FrankaSim {
    /// Start one in `dir` (its log there) and wait until it listens.
    pub(crate) fn start(python: &Path, dir: &Path) -> Self {
        let log = dir.join("franka-sim.log");
        let err = std::fs::File::create(&log).unwrap_or_else(|e| panic!("{e}"));
        let mjcf = root().join("rigs/fr3/fr3_nomesh.xml");
        assert!(
            mjcf.exists(),
            "{} is missing: franka-sim needs the FR3 model offline",
            mjcf.display()
        );
        let mut child = Command::new(python)
            .arg(root().join("scripts/franka-sim-loopback.py"))
            .env("FR3_MJCF", &mjcf)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(err)
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start franka-sim with {}: {e}", python.display()));
        let stdout = child.stdout.take().expect("stdout");
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if let Some(p) = line.strip_prefix("FRANKA_SIM_PORT=") {
                    let _ = tx.send(p.trim().parse::<u16>().ok());
                }
            }
        });
        let port = rx
            .recv_timeout(Duration::from_secs(120))
            .ok()
            .flatten()
            .unwrap_or_else(|| {
                let _ = child.kill();
                panic!(
                    "franka-sim did not report its port within 120 s; its log:\n{}",
                    std::fs::read_to_string(&log).unwrap_or_default()
                )
            });
        Self {
            child: Some(child),
            port,
            log,
        }
    }

    /// `address` for the rig's `[arm]` table.
    #[must_use]
    pub(crate) fn address(&self) -> String {
        format!("127.0.0.1:{}", self.port)
    }

    /// Kill it now (a lost connection, as a cable pulled or a controller rebooted).
    pub(crate) fn kill(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    /// The last lines of its log, for a failure's message.
    #[must_use]
    pub(crate) fn log_tail(&self) -> String {
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        lines[lines.len().saturating_sub(30)..].join("\n")
    }

    /// Asserts its log records no motion the simulator aborted (a limit the robot would
    /// have enforced).
    pub(crate) fn assert_no_abort(&self) {
        if let Some(line) = self.aborted_a_motion() {
            panic!(
                "franka-sim aborted a motion: {line}\nits log up to there:\n{}",
                self.log_before(&line, 40)
            );
        }
    }

    /// Up to `n` lines of its log that come before `line`, and `line`.
    #[must_use]
    pub(crate) fn log_before(&self, line: &str, n: usize) -> String {
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        let at = lines.iter().position(|l| *l == line).unwrap_or(lines.len());
        lines[at.saturating_sub(n)..(at + 1).min(lines.len())].join("\n")
    }

    /// The first line of its log that records an aborted motion: every reflex
    /// franka-sim emulates logs "-- aborting the motion" (a motion limit, a
    /// discontinuity of the joints' inverse kinematics, lost commands).
    #[must_use]
    pub(crate) fn aborted_a_motion(&self) -> Option<String> {
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        text.lines()
            .find(|l| {
                l.contains("aborting the motion")
                    || (l.contains("violation") && !l.contains("enforce"))
            })
            .map(str::to_owned)
    }
}

impl Drop for FrankaSim {
    fn drop(&mut self) {
        self.kill();
    }
}

/// Polls `f` until it is true or `limit` passes.
pub(crate) fn wait_until(limit: Duration, mut f: impl FnMut() -> bool) -> bool {
    let t0 = Instant::now();
    while t0.elapsed() < limit {
        if f() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    f()
}

/// A rig file: the Franka at `address` (real time not enforced: CI has no PREEMPT_RT
/// kernel), the rod frame turned so the finger points down as the FR3 does at its home
/// keyframe, rotations kept within ±0.4 rad of it, and the other devices as given.
#[must_use]
pub(crate) fn rig_toml(address: &str, devices: &str, limits: &str) -> String {
    format!(
        r#"[arm]
driver = "franka"
address = "{address}"
reflex_force_n = 30.0
realtime = "ignore"

{devices}

[workspace]
x_m = [-0.01, 0.06]
z_m = [-0.06, 0.06]
theta_rad = [-0.4, 0.4]
# The rod's axis along the base's -z, turned 45° about it: the finger at theta = 0 is
# the FR3's flange at its home keyframe (no turn of the wrist to start with).
base_from_rod = {{ translation_m = [0.58, 0.0, 0.6], rotation_wxyz = [0.0, 0.9238795325112867, -0.3826834323650898, 0.0] }}
home = {{ x_m = -0.03, z_m = 0.0, theta_rad = 0.0 }}
reach_in_base_m = [[0.25, 0.75], [-0.2, 0.2], [0.1, 0.8]]

[limits]
{limits}
sensor_range_force_n = [50.0, 50.0, 70.0]
sensor_range_torque_nm = [1.0, 1.0, 1.0]

[procedure]
approach_speed_m_s = 0.05
settle_s = 0.3
ft_window_s = 0.05
min_window_readings = 25
retreat_speed_m_s = 0.1
frame_timeout_s = 0.5
max_attempts = 3
max_consecutive_failures = 10
"#
    )
}

/// The scene: one rod, rotations within the rig's ±0.4 rad, the Nano17's noise.
pub(crate) const SCENE: &str = r#"name = "on-land"
medium = "air"

[poses]
x_m = [0.0, 0.05]
z_m = [-0.05, 0.05]
theta_rad = [-0.4, 0.4]

[[rods]]
name = "circle-10"
shape = "circle"
size_m = 0.01

[[effects]]
kind = "ft_noise"
force_sigma_n = 0.0125
torque_sigma_nm = 0.0000625
"#;

/// Writes `rig.toml` (as [`rig_toml`] makes it) and `scene.toml` ([`SCENE`]) in `dir`.
pub(crate) fn write_rig(dir: &Path, rig: &str) {
    std::fs::write(dir.join("rig.toml"), rig).unwrap_or_else(|e| panic!("{e}"));
    std::fs::write(dir.join("scene.toml"), SCENE).unwrap_or_else(|e| panic!("{e}"));
}

/// Where the rigs below put the rod, in the arm's base frame.
pub(crate) fn base_from_rod() -> softtouch_schemas::ArmPose {
    softtouch_schemas::ArmPose {
        translation_m: [0.58, 0.0, 0.6],
        rotation_wxyz: [0.0, 0.923_879_532_511_286_7, -0.382_683_432_365_089_8, 0.0],
    }
}

/// The rigs' home pose as the arm is sent to it (base frame).
pub(crate) fn home_in_base() -> softtouch_schemas::ArmPose {
    softtouch_schemas::ArmPose::from_contact(
        &base_from_rod(),
        &softtouch_schemas::ContactPose {
            x_m: -0.03,
            z_m: 0.0,
            theta_rad: 0.0,
        },
    )
}

/// The simulated force sensor, camera and gripper.
pub(crate) const SIM_DEVICES: &str = r#"[force_sensor]
driver = "sim"
rate_hz = 1000.0

[camera]
driver = "sim"
fps = 120.0

[gripper]
driver = "sim"
"#;

/// The default limits.
pub(crate) const LIMITS: &str = "max_force_n = 15.0\nmax_torque_nm = 0.8";
