//! franka-sim (PyPI), an independent FCI server, started for one test: MuJoCo's FR3 on
//! loopback, a free port, both enforcement options on (motion limits and
//! communication constraints abort a motion as a robot does).
//!
//! Needs `SOFTTOUCH_FRANKA_SIM_PYTHON`: a Python with franka-sim installed (`.ci/run`
//! makes one; TESTING.md says how by hand). The tier's tests are `#[ignore]`d; asked
//! to run without it (or without socat, or the FR3 model), they fail saying what is
//! missing: a run that ran nothing never passes.
//!
//! Every server records what the driver sent ([`record`]); [`FrankaSim::judge`] is
//! the tier's verdict on it.
#![allow(dead_code)]

pub(crate) mod departures;
pub(crate) mod record;

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

/// The Python that runs franka-sim. The tier's tests are `#[ignore]`d: one asked to
/// run without it fails, naming what to set, rather than passing having run nothing.
pub(crate) fn python() -> PathBuf {
    match std::env::var_os("SOFTTOUCH_FRANKA_SIM_PYTHON") {
        Some(p) if !p.is_empty() => PathBuf::from(p),
        _ => panic!(
            "the franka-sim tier was asked to run, but SOFTTOUCH_FRANKA_SIM_PYTHON is not set: \
             set it to a Python with franka-sim (TESTING.md, the franka-sim tier; .ci/run makes \
             target/franka-sim-venv)"
        ),
    }
}

/// A pty pair from socat, which the tier's Hand-E needs: missing, the test fails.
pub(crate) fn pty() -> crate::pty::PtyPair {
    crate::pty::pty_pair().unwrap_or_else(|| {
        panic!("the franka-sim tier was asked to run, but socat is missing (apt-get install socat)")
    })
}

/// A running franka-sim; killed when dropped.
#[derive(Debug)]
pub(crate) struct FrankaSim {
    child: Option<Child>,
    /// Its FCI command port on 127.0.0.1.
    pub(crate) port: u16,
    /// Its log (stderr).
    pub(crate) log: PathBuf,
    /// What it recorded of the driver's commands ([`record`]).
    pub(crate) record: PathBuf,
}

/// The tier's verdict on one server's record ([`FrankaSim::judge`]).
#[derive(Debug)]
pub(crate) struct Judged {
    /// The driver's commanded signal against the robot's limits.
    pub(crate) verdict: softtouch_drivers::franka::signal::Verdict,
    /// Aborts with cycles lost just before them: the host's, recovered from.
    pub(crate) host_aborts: usize,
    /// Cycles the server closed with no answer in time.
    pub(crate) lost_cycles: usize,
}

impl FrankaSim {
    /// Start one in `dir` (its log there) and wait until it listens.
    pub(crate) fn start(python: &Path, dir: &Path) -> Self {
        Self::start_with(python, dir, &[])
    }

    /// [`FrankaSim::start`] with more arguments for the loopback script (`--no-enforce`:
    /// nothing aborted, so a whole signal is recorded).
    pub(crate) fn start_with(python: &Path, dir: &Path, args: &[&str]) -> Self {
        let log = dir.join("franka-sim.log");
        let err = std::fs::File::create(&log).unwrap_or_else(|e| panic!("{e}"));
        let record = dir.join("franka-sim-record.txt");
        let mjcf = root().join("rigs/fr3/fr3_nomesh.xml");
        assert!(
            mjcf.exists(),
            "{} is missing: franka-sim needs the FR3 model offline",
            mjcf.display()
        );
        let mut child = Command::new(python)
            .arg(root().join("scripts/franka-sim-loopback.py"))
            .arg("--record")
            .arg(&record)
            .args(args)
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
            record,
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

    /// What the server has recorded so far ([`record`]).
    pub(crate) fn recorded(&self) -> record::Record {
        let text = std::fs::read_to_string(&self.record).unwrap_or_else(|e| {
            panic!(
                "cannot read franka-sim's record {}: {e}",
                self.record.display()
            )
        });
        record::Record::parse(&text).unwrap_or_else(|e| panic!("{}: {e}", self.record.display()))
    }

    /// The tier's verdict, from what the server recorded: every command the driver
    /// sent, differenced on the robot's 1 ms clock with no lost cycle in any
    /// difference, holds within the FR3's Cartesian and joint limits; and every motion
    /// the server aborted had cycles lost just before it (the host's: the run under
    /// test must have recovered from it, which its own checks see). An abort with no
    /// lost cycle before it, or a commanded signal over a limit, fails, whatever the
    /// host. Prints the verdict.
    pub(crate) fn judge(&self) -> Judged {
        let rec = self.recorded();
        let verdict = rec.judge();
        let (hosts, drivers): (Vec<_>, Vec<_>) =
            rec.aborts.iter().partition(|a| rec.is_the_hosts(a));
        eprintln!(
            "franka-sim verdict: {} commands ({} late), {} cycles lost, {} aborts ({} the host's)\n{}",
            rec.commands.len(),
            rec.late,
            rec.lost.len(),
            rec.aborts.len(),
            hosts.len(),
            verdict.table()
        );
        for a in &hosts {
            eprintln!(
                "franka-sim: the host's abort (cycles lost before it), recovered: {}",
                a.reason
            );
        }
        if !drivers.is_empty() || !verdict.holds() {
            let kept = self.keep();
            assert!(
                drivers.is_empty(),
                "franka-sim aborted a motion with no cycle lost in the {} before it (the driver's): {:?}\nits log:\n{}\nthe record and log are kept in {kept}",
                record::LOST_BEFORE_ABORT,
                drivers,
                self.log_tail()
            );
            panic!(
                "the driver's commanded signal breaks the FR3's limits:\n{}\nthe record and log are kept in {kept}",
                verdict.table()
            );
        }
        assert!(verdict.commands > 0, "franka-sim recorded no command");
        Judged {
            verdict,
            host_aborts: hosts.len(),
            lost_cycles: rec.lost.len(),
        }
    }
}

impl FrankaSim {
    /// Copies the record and the log of a failed test to
    /// `target/franka-sim-failed/TEST/` (the test's folder is removed when it ends),
    /// and says where.
    fn keep(&self) -> String {
        let test = std::thread::current()
            .name()
            .unwrap_or("unnamed")
            .replace("::", "-");
        let dir = root().join("target/franka-sim-failed").join(test);
        let kept = std::fs::create_dir_all(&dir)
            .and_then(|()| std::fs::copy(&self.record, dir.join("franka-sim-record.txt")))
            .and_then(|_| std::fs::copy(&self.log, dir.join("franka-sim.log")));
        match kept {
            Ok(_) => dir.display().to_string(),
            Err(e) => format!("nowhere ({}: {e})", dir.display()),
        }
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
# A rig's own share of the FR3's limits (the default, said): 2.7 m/s², 900 m/s³.
motion_margin = 0.3

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
