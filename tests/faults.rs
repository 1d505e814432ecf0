//! The fault-injection matrix of collection: one test per way a run can go wrong.
//!
//! Each in-process test runs the real job ([`collect`]) on the simulated rig, with the
//! devices wrapped behind their own traits by fault injectors (a sensor that spikes
//! mid-packet, sends NaN, errs or stalls; a camera that times out; an arm that records
//! its commands and lets the test read where it ended). Virtual time throughout. Each
//! asserts the arm's final state, the run's status, its events, and that every
//! sample the job reported done is in the database. The process-level paths (SIGTERM,
//! a second process resuming a leased run) run the `softtouch` binary.

use crate::common;
use common::{runtime, softtouch, tempdir, text};

use async_trait::async_trait;
use softtouch_collector::collect::rods::RodChanger;
use softtouch_collector::collect::{
    CollectDevices, CollectPlan, Counters, NewRunRequest, Outcome, PlanError, Progress, Resumed,
    build_devices, collect,
};
use softtouch_collector::store::{StoreError, SyncStore};
use softtouch_drivers::{Arm, ArmState, Camera, DeviceError, ForceSensor, Frame};
use softtouch_schemas::{ArmPose, FtReading, TimestampNs};
use sqlx::Row as _;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::watch;

// ---------------------------------------------------------------- injectors

/// What the wrappers share: where the job is, and what the arm was told.
#[derive(Debug, Default)]
struct ProbeState {
    /// An approach move is under way.
    approaching: bool,
    /// Approaches started (each one or two moves from home).
    approaches: u32,
    /// The camera was asked for a frame since the last approach (recording).
    recording: bool,
    /// Frames asked for.
    frame_calls: u32,
    /// Every move target, in order.
    moves: Vec<ArmPose>,
    /// Stop commands.
    stops: u32,
    /// Moves started before the last stop command.
    moves_before_last_stop: usize,
    /// Readings the sensor wrapper spiked or spoilt, with their place in the packet.
    spoilt: Vec<(usize, usize)>,
    /// Joints the arm reports, where it plays an arm with joints: each Cartesian move
    /// drifts joint 3 (the elbow) by 2 mrad, as a robot's redundancy does over a night.
    joints: Option<[f64; 7]>,
    /// Joint-space moves, their targets.
    joint_moves: Vec<[f64; 7]>,
}

type Probe = Arc<Mutex<ProbeState>>;

fn probe(p: &Probe) -> std::sync::MutexGuard<'_, ProbeState> {
    p.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn same_pose(a: &ArmPose, b: &ArmPose) -> bool {
    a.translation_m
        .iter()
        .zip(&b.translation_m)
        .all(|(x, y)| (x - y).abs() < 1e-9)
}

/// The arm, recording its commands; optionally sends a double stop request when an
/// approach starts (a second Ctrl-C mid-move).
struct ProbeArm {
    inner: Arc<tokio::sync::Mutex<Box<dyn Arm>>>,
    probe: Probe,
    home: ArmPose,
    /// The retreat plane's x, rod frame.
    plane_x_m: f64,
    base_from_rod: ArmPose,
    /// At the start of approach `n`: the stop requests `level` stands for (1: SIGTERM,
    /// finish the sample and stop; 2: a second Ctrl-C, stop where it is).
    stop_on_approach: Option<(u32, u32, watch::Sender<u32>)>,
}

/// Clears `approaching` however the move ends (done, failed, or dropped mid-way).
struct Approaching(Probe);

impl Drop for Approaching {
    fn drop(&mut self) {
        probe(&self.0).approaching = false;
    }
}

/// Whether `target` lies nearer the rod than the retreat plane (at `plane_x_m`, rod
/// frame): a move there is an approach.
fn toward_rod(base_from_rod: &ArmPose, plane_x_m: f64, target: &ArmPose) -> bool {
    softtouch_schemas::ContactPose::from_arm(base_from_rod, target).x_m > plane_x_m + 1e-6
}

#[async_trait]
impl Arm for ProbeArm {
    async fn move_to(&mut self, target: &ArmPose, speed_m_s: f64) -> Result<ArmState, DeviceError> {
        // An approach moves toward the rod, nearer it than the retreat plane; a leave
        // that stops at the stand-off on its way out is none.
        let inward = |from: &ArmPose, to: &ArmPose| {
            let x =
                |p: &ArmPose| softtouch_schemas::ContactPose::from_arm(&self.base_from_rod, p).x_m;
            toward_rod(&self.base_from_rod, self.plane_x_m, to) && x(to) > x(from) + 1e-6
        };
        let (n, starts) = {
            let mut p = probe(&self.probe);
            let k = p.moves.len();
            let here = p.moves.last().copied().unwrap_or(self.home);
            let approach = inward(&here, target);
            // An approach is two or three moves (free space, contact, its slow end); it
            // starts from its retreat point.
            let was_approach = match k {
                0 => false,
                1 => inward(&self.home, &p.moves[0]),
                _ => inward(&p.moves[k - 2], &p.moves[k - 1]),
            };
            let starts = approach && !was_approach;
            p.moves.push(*target);
            if let Some(q) = p.joints.as_mut() {
                q[2] += 0.002;
            }
            // Any move ends the recording.
            p.recording = false;
            if approach {
                p.approaching = true;
            }
            if starts {
                p.approaches += 1;
            }
            (p.approaches, starts)
        };
        let _clear = Approaching(Arc::clone(&self.probe));
        if starts
            && let Some((at, level, tx)) = &self.stop_on_approach
            && *at == n
        {
            // Well into the move (an approach takes about a second).
            let (tx, level) = (tx.clone(), *level);
            tokio::spawn(async move {
                tokio::time::sleep(Duration::from_millis(200)).await;
                for l in 1..=level {
                    tx.send_replace(l);
                }
            });
        }
        self.inner.lock().await.move_to(target, speed_m_s).await
    }
    async fn state(&mut self) -> Result<ArmState, DeviceError> {
        self.inner.lock().await.state().await
    }
    async fn recover(&mut self) -> Result<(), DeviceError> {
        self.inner.lock().await.recover().await
    }
    async fn joints_rad(&mut self) -> Result<Option<[f64; 7]>, DeviceError> {
        Ok(probe(&self.probe).joints)
    }
    async fn move_joints(&mut self, q_rad: &[f64; 7]) -> Result<Option<ArmState>, DeviceError> {
        {
            let mut p = probe(&self.probe);
            if p.joints.is_none() {
                return Ok(None);
            }
            p.joints = Some(*q_rad);
            p.joint_moves.push(*q_rad);
        }
        self.inner.lock().await.state().await.map(Some)
    }
    async fn stop(&mut self) -> Result<(), DeviceError> {
        {
            let mut p = probe(&self.probe);
            p.stops += 1;
            p.moves_before_last_stop = p.moves.len();
        }
        self.inner.lock().await.stop().await
    }
}

/// A sensor fault to inject.
#[derive(Debug, Clone, Copy, PartialEq)]
enum SensorFault {
    None,
    /// During the first `n` approaches, one reading in the middle of a packet (never
    /// its last) carries `fz_n`.
    MidPacket {
        approaches: u32,
        fz_n: f64,
    },
    /// While recording, for the first `n` frames, the sensor reports a fault.
    ErrorWhileRecording {
        frames: u32,
    },
    /// During the first `n` approaches, no reading arrives.
    StallOnApproach {
        approaches: u32,
    },
    /// After frame call `frame`, no reading arrives for `secs`.
    StallAfterFrame {
        frame: u32,
        secs: f64,
    },
    /// While recording, for the first `n` frames, readings hold NaN.
    NanWhileRecording {
        frames: u32,
    },
}

struct FaultySensor {
    inner: Box<dyn ForceSensor>,
    probe: Probe,
    fault: SensorFault,
    stalled: bool,
}

#[async_trait]
impl ForceSensor for FaultySensor {
    async fn start(&mut self) -> Result<(), DeviceError> {
        self.inner.start().await
    }
    async fn read(&mut self, out: &mut Vec<FtReading>) -> Result<usize, DeviceError> {
        loop {
            let (approaching, approaches, recording, frames) = {
                let p = probe(&self.probe);
                (p.approaching, p.approaches, p.recording, p.frame_calls)
            };
            match self.fault {
                SensorFault::StallOnApproach { approaches: n }
                    if approaching && approaches <= n =>
                {
                    tokio::time::sleep(Duration::from_millis(5)).await;
                }
                SensorFault::StallAfterFrame { frame, secs }
                    if !self.stalled && frames == frame && recording =>
                {
                    self.stalled = true;
                    tokio::time::sleep(Duration::from_secs_f64(secs)).await;
                }
                SensorFault::ErrorWhileRecording { frames: n } if recording && frames <= n => {
                    // Once per frame: the reader task retries after 10 ms.
                    probe(&self.probe).recording = false;
                    return Err(DeviceError::Fault {
                        device: "injected sensor".into(),
                        code: Some(0x20),
                        message: "status word: gauge fault".into(),
                    });
                }
                _ => break,
            }
        }
        let start = out.len();
        let n = self.inner.read(out).await?;
        let packet = &mut out[start..];
        let mut p = probe(&self.probe);
        match self.fault {
            SensorFault::MidPacket { approaches, fz_n }
                if p.approaching && p.approaches <= approaches && packet.len() >= 3 =>
            {
                let mid = packet.len() / 2;
                packet[mid].wrench_in_sensor.force_n[2] = fz_n;
                p.spoilt.push((mid, packet.len()));
            }
            SensorFault::NanWhileRecording { frames }
                if p.recording && p.frame_calls <= frames && !packet.is_empty() =>
            {
                let mid = packet.len() / 2;
                packet[mid].wrench_in_sensor.force_n[0] = f64::NAN;
                p.spoilt.push((mid, packet.len()));
            }
            _ => {}
        }
        Ok(n)
    }
    async fn bias(&mut self) -> Result<(), DeviceError> {
        self.inner.bias().await
    }
    async fn stop(&mut self) -> Result<(), DeviceError> {
        self.inner.stop().await
    }
    fn lost_readings(&self) -> u64 {
        self.inner.lost_readings()
    }
}

/// A camera that times out on the frame calls `timeouts` says (and on the rest
/// frames, where `rest_timeout`).
struct FaultyCamera {
    inner: Box<dyn Camera>,
    probe: Probe,
    timeout: fn(u32) -> bool,
    rest_timeout: bool,
}

#[async_trait]
impl Camera for FaultyCamera {
    async fn frame_after(&mut self, t: TimestampNs, timeout_ms: u64) -> Result<Frame, DeviceError> {
        // The run's rest frames at home, before its first approach: not a sample's
        // frame, not counted.
        if probe(&self.probe).approaches == 0 {
            if self.rest_timeout {
                return Err(DeviceError::Timeout {
                    device: "injected camera".into(),
                    timeout_ms,
                });
            }
            return self.inner.frame_after(t, timeout_ms).await;
        }
        let call = {
            let mut p = probe(&self.probe);
            p.frame_calls += 1;
            p.recording = true;
            p.frame_calls
        };
        if (self.timeout)(call) {
            tokio::time::sleep(Duration::from_millis(timeout_ms)).await;
            return Err(DeviceError::Timeout {
                device: "injected camera".into(),
                timeout_ms,
            });
        }
        self.inner.frame_after(t, timeout_ms).await
    }
    fn dropped_frames(&self) -> u64 {
        self.inner.dropped_frames()
    }
}

/// Rods changed by an operator who never answers, and presses Ctrl-C twice instead.
struct AbsentOperator {
    first: bool,
    stop: watch::Sender<u32>,
}

#[async_trait]
impl RodChanger for AbsentOperator {
    async fn change_rod(&mut self, _rod: &str) -> Result<(), DeviceError> {
        if self.first {
            self.first = false;
            return Ok(());
        }
        self.stop.send_replace(1);
        self.stop.send_replace(2);
        std::future::pending().await
    }
}

/// Records which samples the job reported done.
#[derive(Default)]
struct Done(Vec<u64>);

impl Progress for Done {
    fn sample_done(&mut self, index: u64, _c: &Counters) {
        self.0.push(index);
    }
    fn note(&mut self, _message: &str) {}
}

// ---------------------------------------------------------------- one faulty run

/// What to inject.
struct Faults {
    sensor: SensorFault,
    camera_timeout: fn(u32) -> bool,
    /// The camera gives no rest frame at the run's start (before its first approach).
    rest_camera_timeout: bool,
    /// A double stop request at the start of this approach.
    stop_on_approach: Option<u32>,
    /// One stop request (as SIGTERM sends) at the start of this approach.
    term_on_approach: Option<u32>,
    /// An absent operator at the first rod change (with two rods of `block` samples).
    absent_operator: bool,
    /// Two rods of two samples each, changed by the simulated operator.
    two_rods: bool,
    /// The arm reports joints (and its elbow drifts): see [`ProbeState::joints`].
    joints: bool,
    /// Before collecting: change the plan (e.g. poses outside the workspace).
    edit_plan: fn(&mut CollectPlan),
    /// Before collecting: SQL run on the database from another connection.
    sql: String,
}

impl Default for Faults {
    fn default() -> Self {
        Self {
            sensor: SensorFault::None,
            camera_timeout: |_| false,
            rest_camera_timeout: false,
            stop_on_approach: None,
            term_on_approach: None,
            absent_operator: false,
            two_rods: false,
            joints: false,
            edit_plan: |_| {},
            sql: String::new(),
        }
    }
}

/// How a faulty run ended.
struct Ended {
    outcome: Outcome,
    counters: Counters,
    done: Vec<u64>,
    probe: ProbeState,
    home: ArmPose,
    /// The retreat plane's x, rod frame.
    plane_x_m: f64,
    /// The arm's pose at the end, and 5 s (virtual) later.
    final_pose: ArmPose,
    later_pose: ArmPose,
    run_id: i64,
}

impl Ended {
    fn at_home(&self) -> bool {
        same_pose(&self.final_pose, &self.home)
    }
    /// The arm is not moving: the world's pose did not change in 5 s.
    fn still(&self) -> bool {
        same_pose(&self.final_pose, &self.later_pose)
    }

    /// Every approach starts at its retreat point, and every move after an approach
    /// (whatever ended it: the sample, a guard trip, a fault, a stop) goes straight
    /// back along the approach axis: to the retreat plane (`plane_x_m`) with the
    /// approach's z and θ, nothing turned. How many departures there were.
    fn departures_along_the_approach_axis(&self, base_from_rod: &ArmPose) -> usize {
        use softtouch_schemas::ContactPose;
        let c = |p: &ArmPose| ContactPose::from_arm(base_from_rod, p);
        let plane_x = self.plane_x_m;
        let moves = &self.probe.moves;
        let mut departures = 0;
        for (k, pair) in moves.windows(2).enumerate() {
            let (a, b) = (c(&pair[0]), c(&pair[1]));
            let into = toward_rod(base_from_rod, self.plane_x_m, &pair[1]);
            let from = toward_rod(base_from_rod, self.plane_x_m, &pair[0]);
            let same_line =
                (a.z_m - b.z_m).abs() < 1e-9 && (a.theta_rad - b.theta_rad).abs() < 1e-9;
            if into && !from {
                assert!(
                    same_line && (a.x_m - plane_x).abs() < 1e-9,
                    "move {} approaches from {a:?}, not from its retreat point, to {b:?}",
                    k + 1
                );
            }
            if into && from {
                assert!(
                    same_line,
                    "move {} turns on the approach line: {a:?} to {b:?}",
                    k + 1
                );
            }
            if from && !into {
                departures += 1;
                assert!(
                    same_line && (b.x_m - plane_x).abs() < 1e-9,
                    "move {} leaves {a:?} for {b:?}: not straight back along the approach axis",
                    k + 1
                );
            }
        }
        departures
    }
}

fn faulty_run(db: &Path, samples: u64, faults: Faults) -> Ended {
    if !faults.sql.is_empty() {
        runtime().block_on(async {
            let store = common::open_store(db).await;
            sqlx::raw_sql(sqlx::AssertSqlSafe(faults.sql))
                .execute(store.pool())
                .await
                .unwrap_or_else(|e| panic!("{e}"));
            store.close().await;
        });
    }
    let store = SyncStore::open(common::target_of(db)).unwrap_or_else(|e| panic!("{e}"));
    let request = NewRunRequest {
        samples,
        seed: Some(3),
        rods: if faults.absent_operator || faults.two_rods {
            vec!["circle-10".into(), "square-10".into()]
        } else {
            Vec::new()
        },
        block: Some(if faults.absent_operator || faults.two_rods {
            2
        } else {
            samples.max(1)
        }),
        ..NewRunRequest::default()
    };
    let mut plan = CollectPlan::new_run(&store, &request).unwrap_or_else(|e| panic!("{e}"));
    // These faults are injected at an index and checked at it: index order (the
    // planned order's faults are the binary's tests below and tests/resume.rs).
    plan.rig.procedure.visit_order = softtouch_schemas::rig::VisitOrder::Index;
    (faults.edit_plan)(&mut plan);
    let ended = softtouch_collector::testing::block_on(async {
        let (devices, clock) = build_devices(&plan.rig, &plan.scene, plan.seed)
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        let w = &plan.rig.workspace;
        let home = ArmPose::from_contact(&w.base_from_rod, &w.home);
        let plane_x_m = softtouch_collector::collect::retreat_x_m(w.home.x_m, &plan.rig.procedure);
        let shared: Probe = Probe::default();
        if faults.joints {
            probe(&shared).joints = Some([0.0, -0.3, 0.0, -2.2, 0.0, 1.9, 0.6]);
        }
        let arm = Arc::new(tokio::sync::Mutex::new(devices.arm));
        let (stop_tx, stop_rx) = watch::channel(0u32);
        let wrapped = CollectDevices {
            arm: Box::new(ProbeArm {
                inner: Arc::clone(&arm),
                probe: Arc::clone(&shared),
                home,
                plane_x_m,
                base_from_rod: w.base_from_rod,
                stop_on_approach: faults
                    .stop_on_approach
                    .map(|n| (n, 2, stop_tx.clone()))
                    .or_else(|| faults.term_on_approach.map(|n| (n, 1, stop_tx.clone()))),
            }),
            force_sensor: Box::new(FaultySensor {
                inner: devices.force_sensor,
                probe: Arc::clone(&shared),
                fault: faults.sensor,
                stalled: false,
            }),
            camera: Box::new(FaultyCamera {
                inner: devices.camera,
                probe: Arc::clone(&shared),
                timeout: faults.camera_timeout,
                rest_timeout: faults.rest_camera_timeout,
            }),
            rods: if faults.absent_operator {
                Box::new(AbsentOperator {
                    first: true,
                    stop: stop_tx.clone(),
                })
            } else {
                devices.rods
            },
        };
        let mut done = Done::default();
        let (outcome, counters) = collect(&store, &plan, wrapped, clock, stop_rx, &mut done).await;
        drop(stop_tx);
        let pose = |arm: Arc<tokio::sync::Mutex<Box<dyn Arm>>>| async move {
            arm.lock()
                .await
                .state()
                .await
                .unwrap_or_else(|e| panic!("{e}"))
                .base_from_finger
        };
        let final_pose = pose(Arc::clone(&arm)).await;
        tokio::time::sleep(Duration::from_secs(5)).await;
        let later_pose = pose(arm).await;
        let state = std::mem::take(&mut *probe(&shared));
        Ended {
            outcome,
            counters,
            done: done.0,
            probe: state,
            home,
            plane_x_m,
            final_pose,
            later_pose,
            run_id: plan.run_id,
        }
    });
    store.close();
    ended
}

/// The run's status, its events `(kind, message)`, and its stored samples
/// `(index, status, reject_reason, attempts)`.
struct Stored {
    status: String,
    events: Vec<(String, String)>,
    samples: Vec<(u64, String, Option<String>, i64)>,
    lease_held: bool,
}

impl Stored {
    fn kinds(&self, kind: &str) -> Vec<&str> {
        self.events
            .iter()
            .filter(|(k, _)| k == kind)
            .map(|(_, m)| m.as_str())
            .collect()
    }
    fn indices(&self) -> Vec<u64> {
        self.samples.iter().map(|s| s.0).collect()
    }
}

fn stored(db: &Path, run: i64) -> Stored {
    runtime().block_on(async {
        let store = common::open_store(db).await;
        let status = store
            .run_record(run)
            .await
            .unwrap_or_else(|e| panic!("{e}"))
            .status;
        let events = store
            .events(run, 10_000)
            .await
            .unwrap_or_else(|e| panic!("{e}"))
            .into_iter()
            .map(|e| (e.kind, e.message))
            .collect();
        let samples = sqlx::query(store.dialect().sql(
            "SELECT sample_index, status, reject_reason, attempts FROM samples
             WHERE run_id = ? ORDER BY sample_index",
        ))
        .bind(run)
        .fetch_all(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"))
        .iter()
        .map(|r| {
            (
                u64::try_from(r.get::<i64, _>(0)).unwrap_or(u64::MAX),
                r.get(1),
                r.get(2),
                r.get(3),
            )
        })
        .collect();
        let lease_held = store
            .lease(run)
            .await
            .unwrap_or_else(|e| panic!("{e}"))
            .is_some();
        store.close().await;
        Stored {
            status,
            events,
            samples,
            lease_held,
        }
    })
}

/// Every sample the job reported done is stored, and nothing else.
fn nothing_lost(ended: &Ended, s: &Stored) {
    let mut done = ended.done.clone();
    done.sort_unstable();
    assert_eq!(
        s.indices(),
        done,
        "stored samples = samples the job reported done"
    );
    assert!(!s.lease_held, "the lease is given back at the end");
}

// ---------------------------------------------------------------- the matrix

#[test]
fn a_force_spike_in_the_middle_of_a_packet_trips_the_guard() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    let e = faulty_run(
        &db,
        4,
        Faults {
            sensor: SensorFault::MidPacket {
                approaches: 1,
                fz_n: 30.0,
            },
            ..Faults::default()
        },
    );
    let s = stored(&db, e.run_id);
    assert_eq!(e.outcome, Outcome::Completed);
    assert_eq!(s.status, "completed");
    let (mid, len) = e.probe.spoilt[0];
    assert!(
        mid + 1 < len,
        "the spike was not the packet's newest reading"
    );
    assert_eq!(s.kinds("force_limit").len(), 1, "{:?}", s.events);
    assert!(
        s.kinds("force_limit")[0].contains("30"),
        "{:?}",
        s.kinds("force_limit")
    );
    assert_eq!(
        s.samples[0],
        (0, "rejected".into(), Some("force_limit".into()), 1)
    );
    assert!(s.samples[1..].iter().all(|x| x.1 == "ok"));
    assert!(e.probe.stops >= 1, "the arm was told to stop at the trip");
    assert!(e.at_home() && e.still(), "the arm ends at home, still");
    let w = softtouch_schemas::defaults::rig().workspace;
    assert!(e.departures_along_the_approach_axis(&w.base_from_rod) >= 4);
    nothing_lost(&e, &s);
}

/// The finger leaves the rod the way it came, from every pose where it may touch it:
/// a guard trip on every sample (0.3 N: below the first contact's force, 24 σ of the
/// Nano17's noise, which 0.05 N is not), across a
/// block's end (two rods), in the planned and the index order, and normal samples.
/// Nothing turns or travels before the arm is back at the retreat plane.
#[test]
fn every_departure_from_the_rod_runs_back_along_the_approach_axis() {
    for order in [
        softtouch_schemas::rig::VisitOrder::Planned,
        softtouch_schemas::rig::VisitOrder::Index,
    ] {
        for trip in [true, false] {
            let dir = tempdir();
            let db = dir.path().join("t.db");
            let edit: fn(&mut CollectPlan) = match (order, trip) {
                (softtouch_schemas::rig::VisitOrder::Planned, true) => |p| {
                    p.rig.procedure.visit_order = softtouch_schemas::rig::VisitOrder::Planned;
                    p.rig.limits.max_force_n = 0.3;
                },
                (softtouch_schemas::rig::VisitOrder::Planned, false) => |p| {
                    p.rig.procedure.visit_order = softtouch_schemas::rig::VisitOrder::Planned;
                },
                (_, true) => |p| p.rig.limits.max_force_n = 0.3,
                (_, false) => |_| {},
            };
            let e = faulty_run(
                &db,
                4,
                Faults {
                    two_rods: true,
                    edit_plan: edit,
                    ..Faults::default()
                },
            );
            let s = stored(&db, e.run_id);
            let context = format!("{order:?}, trip {trip}: {:?}", s.events);
            assert_eq!(e.outcome, Outcome::Completed, "{context}");
            assert_eq!(s.samples.len(), 4, "{context}");
            assert_eq!(s.kinds("rod_change").len(), 2, "{context}");
            if trip {
                assert!(
                    s.samples
                        .iter()
                        .all(|x| x.2.as_deref() == Some("force_limit")),
                    "{context}"
                );
            } else {
                assert!(s.samples.iter().all(|x| x.1 == "ok"), "{context}");
            }
            let w = softtouch_schemas::defaults::rig().workspace;
            let departures = e.departures_along_the_approach_axis(&w.base_from_rod);
            assert!(departures >= 4, "{departures} departures: {context}");
            assert!(e.at_home() && e.still(), "{context}");
        }
    }
}

/// On an arm with joints, the elbow goes back in joint space to where the run first
/// found it at home, at each block's end, with its drift logged; an arm without
/// joints (the simulator) logs nothing and moves nothing.
#[test]
fn the_elbow_goes_back_to_homes_joints_at_each_blocks_end() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    let e = faulty_run(
        &db,
        4,
        Faults {
            two_rods: true,
            joints: true,
            ..Faults::default()
        },
    );
    let s = stored(&db, e.run_id);
    assert_eq!(e.outcome, Outcome::Completed, "{:?}", s.events);
    let elbow = s.kinds("elbow");
    assert_eq!(elbow.len(), 2, "one per block's end: {:?}", s.events);
    for m in &elbow {
        assert!(
            m.starts_with("block's end: the joints drifted at most") && m.contains("(joint 3)"),
            "{m}"
        );
        assert!(m.contains("moved back in joint space"), "{m}");
    }
    assert_eq!(e.probe.joint_moves.len(), 2, "{:?}", e.probe.joint_moves);
    for q in &e.probe.joint_moves {
        // Where the run first reached home: one move in (2 mrad of drift).
        assert!((q[2] - 0.002).abs() < 1e-12, "{q:?}");
    }
    // No joints: nothing logged, nothing moved.
    let dir = tempdir();
    let db = dir.path().join("t.db");
    let e = faulty_run(
        &db,
        4,
        Faults {
            two_rods: true,
            ..Faults::default()
        },
    );
    assert!(stored(&db, e.run_id).kinds("elbow").is_empty());
    assert!(e.probe.joint_moves.is_empty());
}

/// A stop request (as SIGTERM sends) during an approach: the sample finishes, the arm
/// leaves the rod along the approach axis and goes home, the run is `stopped`.
#[test]
fn a_stop_request_mid_approach_finishes_the_sample_and_leaves_along_the_axis() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    let e = faulty_run(
        &db,
        6,
        Faults {
            term_on_approach: Some(2),
            ..Faults::default()
        },
    );
    let s = stored(&db, e.run_id);
    assert_eq!(e.outcome, Outcome::Stopped, "{:?}", s.events);
    assert_eq!(s.status, "stopped");
    assert_eq!(s.indices(), [0, 1], "the sample under way finished");
    let w = softtouch_schemas::defaults::rig().workspace;
    assert!(e.departures_along_the_approach_axis(&w.base_from_rod) >= 2);
    assert!(e.at_home() && e.still());
    nothing_lost(&e, &s);
}

#[test]
fn a_pose_outside_the_workspace_is_never_sent_and_stops_the_run() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    let e = faulty_run(
        &db,
        3,
        Faults {
            edit_plan: |plan| {
                plan.scene.poses.x_m = softtouch_schemas::Range::new(5.0, 5.0);
            },
            ..Faults::default()
        },
    );
    let s = stored(&db, e.run_id);
    let Outcome::SafeStop { reason } = &e.outcome else {
        panic!("{:?}", e.outcome)
    };
    assert!(reason.contains("outside the workspace"), "{reason}");
    assert_eq!(s.status, "failed");
    assert_eq!(s.kinds("safe_stop").len(), 1);
    assert!(
        e.probe.moves.iter().all(|m| same_pose(m, &e.home)),
        "only home was ever commanded"
    );
    assert!(e.at_home() && e.still());
    assert!(s.samples.is_empty());
    nothing_lost(&e, &s);
}

#[test]
fn consecutive_failures_end_in_a_safe_stop() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    // Every frame times out: each sample is rejected after its attempts.
    let e = faulty_run(
        &db,
        30,
        Faults {
            camera_timeout: |_| true,
            ..Faults::default()
        },
    );
    let s = stored(&db, e.run_id);
    let Outcome::SafeStop { reason } = &e.outcome else {
        panic!("{:?}", e.outcome)
    };
    assert!(reason.contains("10 samples in a row failed"), "{reason}");
    assert_eq!(s.status, "failed");
    assert_eq!(s.kinds("safe_stop"), [reason.as_str()]);
    assert_eq!(s.samples.len(), 10);
    assert!(
        s.samples
            .iter()
            .all(|x| x.1 == "rejected" && x.2.as_deref() == Some("frame_timeout") && x.3 == 3)
    );
    assert_eq!(s.kinds("frame_timeout").len(), 30);
    assert!(e.at_home() && e.still());
    nothing_lost(&e, &s);
}

#[test]
fn a_frame_timeout_is_retried_and_logged() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    let e = faulty_run(
        &db,
        3,
        Faults {
            camera_timeout: |call| call == 2,
            ..Faults::default()
        },
    );
    let s = stored(&db, e.run_id);
    assert_eq!(e.outcome, Outcome::Completed);
    assert_eq!(s.status, "completed");
    assert_eq!(e.counters.frame_timeouts, 1);
    assert_eq!(s.kinds("frame_timeout").len(), 1);
    assert_eq!(s.samples[1], (1, "ok".into(), None, 2), "retried once");
    assert!(e.at_home() && e.still());
    nothing_lost(&e, &s);
}

/// No rest frame at home: a warning, and the run collects every sample without them.
#[test]
fn a_camera_that_gives_no_rest_frame_is_a_warning_and_the_run_goes_on() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    let e = faulty_run(
        &db,
        3,
        Faults {
            rest_camera_timeout: true,
            ..Faults::default()
        },
    );
    let s = stored(&db, e.run_id);
    assert_eq!(e.outcome, Outcome::Completed);
    assert_eq!(s.status, "completed");
    let warned = s.kinds("frame_timeout");
    assert!(
        warned.len() == 1 && warned[0].contains("no rest frame from the camera at home"),
        "{:?}",
        s.events
    );
    let kept: i64 = runtime().block_on(async {
        let store = common::open_store(&db).await;
        let n = sqlx::query_scalar("SELECT COUNT(*) FROM rest_frames")
            .fetch_one(store.pool())
            .await
            .expect("count");
        store.close().await;
        n
    });
    assert_eq!(kept, 0);
    nothing_lost(&e, &s);
    // The same run with a camera that answers keeps 8.
    let db = dir.path().join("u.db");
    let e = faulty_run(&db, 3, Faults::default());
    assert_eq!(e.outcome, Outcome::Completed);
    let kept: i64 = runtime().block_on(async {
        let store = common::open_store(&db).await;
        let n = sqlx::query_scalar("SELECT COUNT(*) FROM rest_frames")
            .fetch_one(store.pool())
            .await
            .expect("count");
        store.close().await;
        n
    });
    assert_eq!(kept, 8);
}

#[test]
fn a_sensor_fault_while_recording_is_retried_and_logged() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    let e = faulty_run(
        &db,
        3,
        Faults {
            sensor: SensorFault::ErrorWhileRecording { frames: 1 },
            ..Faults::default()
        },
    );
    let s = stored(&db, e.run_id);
    assert_eq!(e.outcome, Outcome::Completed);
    assert_eq!(s.status, "completed");
    let faults = s.kinds("sensor_fault");
    assert_eq!(faults.len(), 1, "{:?}", s.events);
    assert!(faults[0].contains("gauge fault"), "{faults:?}");
    assert_eq!(s.samples[0], (0, "ok".into(), None, 2));
    assert!(s.kinds("stream_counts")[0].contains("1 read errors"));
    assert!(e.at_home() && e.still());
    nothing_lost(&e, &s);
}

#[test]
fn a_stream_stalled_during_the_approach_stops_the_arm() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    let e = faulty_run(
        &db,
        3,
        Faults {
            sensor: SensorFault::StallOnApproach { approaches: 1 },
            ..Faults::default()
        },
    );
    let s = stored(&db, e.run_id);
    assert_eq!(e.outcome, Outcome::Completed);
    let stops = s.kinds("guard_stop");
    assert_eq!(stops.len(), 1, "{:?}", s.events);
    assert!(stops[0].contains("stale stream"), "{stops:?}");
    assert!(e.probe.stops >= 1, "the arm was told to stop");
    assert_eq!(s.samples[0], (0, "ok".into(), None, 2));
    assert!(e.at_home() && e.still());
    nothing_lost(&e, &s);
}

#[test]
fn a_window_cut_short_by_a_stalled_stream_is_rejected_with_its_reason() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    let e = faulty_run(
        &db,
        3,
        Faults {
            // Past the window's deadline (its end + frame_timeout_s = 0.525 s), over
            // before the retreat (≥ 0.56 s) brings the next attempt's guard.
            sensor: SensorFault::StallAfterFrame {
                frame: 1,
                secs: 1.0,
            },
            ..Faults::default()
        },
    );
    let s = stored(&db, e.run_id);
    assert_eq!(e.outcome, Outcome::Completed);
    let stalled = s.kinds("stream_stalled");
    assert_eq!(stalled.len(), 1, "{:?}", s.events);
    assert!(stalled[0].contains("attempt 1"), "{stalled:?}");
    assert_eq!(s.samples[0], (0, "ok".into(), None, 2), "retried");
    assert!(e.at_home() && e.still());
    nothing_lost(&e, &s);
}

#[test]
fn non_finite_readings_reject_the_window_and_never_reach_a_label_column() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    // NaN in every attempt of sample 0 (3 frames): stored rejected, the run goes on.
    let e = faulty_run(
        &db,
        3,
        Faults {
            sensor: SensorFault::NanWhileRecording { frames: 3 },
            ..Faults::default()
        },
    );
    let s = stored(&db, e.run_id);
    assert_eq!(e.outcome, Outcome::Completed);
    assert_eq!(s.status, "completed");
    assert_eq!(
        s.samples[0],
        (0, "rejected".into(), Some("non_finite".into()), 3)
    );
    assert_eq!(s.kinds("non_finite").len(), 3);
    assert!(s.samples[1..].iter().all(|x| x.1 == "ok"));
    runtime().block_on(async {
        let store = common::open_store(&db).await;
        let fx: f64 = sqlx::query_scalar(
            store
                .dialect()
                .sql("SELECT fx_n FROM samples WHERE sample_index = 0"),
        )
        .fetch_one(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(fx.is_finite());
        store.close().await;
    });
    assert!(e.at_home() && e.still());
    nothing_lost(&e, &s);
}

#[test]
fn a_second_stop_request_mid_move_stops_the_arm_where_it_is() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    let e = faulty_run(
        &db,
        5,
        Faults {
            stop_on_approach: Some(3),
            ..Faults::default()
        },
    );
    let s = stored(&db, e.run_id);
    assert_eq!(e.outcome, Outcome::Stopped);
    assert_eq!(s.status, "stopped");
    let interrupted = s.kinds("interrupted");
    assert_eq!(interrupted.len(), 1, "{:?}", s.events);
    assert!(interrupted[0].contains("not sent home"));
    // The third approach was cut: the last command was that approach, then a stop.
    let last = e.probe.moves.last().copied().unwrap_or(e.home);
    assert!(!same_pose(&last, &e.home), "no retreat after a forced stop");
    assert_eq!(e.probe.moves_before_last_stop, e.probe.moves.len());
    assert!(
        !e.at_home() && !same_pose(&e.final_pose, &last),
        "stopped mid-path"
    );
    assert!(e.still(), "and it stays there");
    assert_eq!(
        s.indices(),
        [0, 1],
        "two samples done, the third not stored"
    );
    nothing_lost(&e, &s);
}

#[test]
fn a_second_stop_request_interrupts_the_rod_change_prompt() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    let e = faulty_run(
        &db,
        4,
        Faults {
            absent_operator: true,
            ..Faults::default()
        },
    );
    let s = stored(&db, e.run_id);
    assert_eq!(e.outcome, Outcome::Stopped);
    assert_eq!(s.status, "stopped");
    assert_eq!(s.kinds("interrupted").len(), 1);
    assert!(
        e.at_home() && e.still(),
        "the prompt waits with the arm at home"
    );
    assert_eq!(s.indices(), [0, 1]);
    nothing_lost(&e, &s);
}

#[test]
fn a_store_that_fails_mid_run_ends_in_a_safe_stop_and_resume_fills_the_gap() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    let e = faulty_run(
        &db,
        6,
        Faults {
            // Sample inserts fail from index 2 on (as a full disk would: the trigger
            // aborts the insert; events and status still go through).
            sql: common::fail_inserts_from(2),
            ..Faults::default()
        },
    );
    let s = stored(&db, e.run_id);
    let Outcome::SafeStop { reason } = &e.outcome else {
        panic!("{:?}", e.outcome)
    };
    assert!(
        reason.contains("the store failed") && reason.contains("disk is full"),
        "{reason}"
    );
    assert_eq!(s.status, "failed");
    assert_eq!(s.kinds("safe_stop"), [reason.as_str()]);
    assert_eq!(
        s.indices(),
        [0, 1],
        "nothing committed past the failed sample"
    );
    assert!(
        e.at_home() && e.still(),
        "the arm went home despite the store"
    );
    let w = softtouch_schemas::defaults::rig().workspace;
    assert!(e.departures_along_the_approach_axis(&w.base_from_rod) >= 2);
    assert!(!s.lease_held);
    // Whether the job saw sample 2 as done depends on when the writer failed (the
    // commit runs beside the job); either way it is not stored, and resume takes it.
    assert!(e.done.starts_with(&[0, 1]), "{:?}", e.done);

    // The disk is freed; a resume takes every missing index.
    runtime().block_on(async {
        let store = common::open_store(&db).await;
        sqlx::raw_sql(common::stop_failing())
            .execute(store.pool())
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        store.close().await;
    });
    let out = softtouch(
        dir.path(),
        &["--db", "t.db", "collect", "--resume", &e.run_id.to_string()],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let s = stored(&db, e.run_id);
    assert_eq!(s.status, "completed");
    assert_eq!(s.indices(), (0..6).collect::<Vec<_>>());
}

#[test]
fn a_run_whose_store_holds_a_gap_is_not_completed_until_the_gap_is_filled() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    let out = softtouch(
        dir.path(),
        &["--db", "t.db", "collect", "--samples", "6", "--seed", "4"],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    // A hole below the highest index (as a write lost mid-run leaves).
    runtime().block_on(async {
        let store = common::open_store(&db).await;
        sqlx::query(
            store
                .dialect()
                .sql("DELETE FROM samples WHERE sample_index IN (1, 3)"),
        )
        .execute(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        store.close().await;
    });
    let store = SyncStore::open(common::target_of(&db)).unwrap_or_else(|e| panic!("{e}"));
    let Resumed::Plan(plan) = CollectPlan::resume(&store, 1).unwrap_or_else(|e| panic!("{e}"))
    else {
        panic!("a run with gaps is not complete")
    };
    assert_eq!(plan.indices().collect::<Vec<_>>(), [1, 3]);
    assert_eq!(plan.remaining(), 2);
    drop(plan);
    store.close();
    // This (live) test process now holds the run's lease: another process is refused.
    let out = softtouch(dir.path(), &["--db", "t.db", "collect", "--resume", "1"]);
    common::fails_with(
        &out,
        1,
        &format!("being collected by process {}", std::process::id()),
    );
    runtime().block_on(async {
        let store = common::open_store(&db).await;
        // Given back, as the job would at its end.
        sqlx::query(store.dialect().sql("DELETE FROM run_leases"))
            .execute(store.pool())
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        store.close().await;
    });
    let out = softtouch(dir.path(), &["--db", "t.db", "collect", "--resume", "1"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("2 ok"), "{}", text(&out.stdout));
    let s = stored(&db, 1);
    assert_eq!(s.status, "completed");
    assert_eq!(s.indices(), (0..6).collect::<Vec<_>>());
}

#[test]
fn a_failed_start_leaves_no_running_run() {
    let dir = tempdir();
    // A real serial sensor on a port that does not exist: the devices cannot be built.
    let rig = common::ok(&softtouch(dir.path(), &["config", "show", "rig"]));
    // (Past the commented example at the top of the file.)
    let at = 1 + rig
        .find("\n[force_sensor]")
        .unwrap_or_else(|| panic!("{rig}"));
    let end = rig[at + 1..].find("\n[").map_or(rig.len(), |i| at + 1 + i);
    let broken = format!(
        "{}[force_sensor]\ndriver = \"ati-serial\"\nport = \"/nonexistent/ttySOFTTOUCH\"\nbaud = 9600\n\
         counts_per_force = 1000000.0\ncounts_per_torque = 1000000.0\n{}",
        &rig[..at],
        &rig[end..]
    );
    // The timings a 9600-baud box can meet (about 15 readings a second), so that the
    // rig passes its check and fails only at the port.
    let broken = broken
        .replace(
            "ft_window_s = 0.05 ",
            "ft_window_s = 2.0\nft_stale_s = 0.2 ",
        )
        .replace("min_window_readings = 25", "min_window_readings = 20");
    std::fs::write(dir.path().join("rig.toml"), broken).unwrap_or_else(|e| panic!("{e}"));
    let out = softtouch(
        dir.path(),
        &[
            "--db",
            "t.db",
            "collect",
            "--rig",
            "rig.toml",
            "--samples",
            "3",
        ],
    );
    common::fails_with(&out, 1, "force_sensor");
    let s = stored(&dir.path().join("t.db"), 1);
    assert_eq!(s.status, "failed");
    let failed = s.kinds("start_failed");
    assert_eq!(failed.len(), 1, "{:?}", s.events);
    assert!(failed[0].contains("force_sensor"), "{failed:?}");
    assert!(s.samples.is_empty() && !s.lease_held);
}

// ---------------------------------------------------------------- processes

/// Samples of `run` so far, read without migrating (a child owns the database).
fn count_samples(db: &Path, run: i64) -> i64 {
    runtime().block_on(async { common::samples_in(db, run).await })
}

/// Samples planned for a run that is stopped long before it ends: far more than the
/// test waits for (a simulated sample takes a few milliseconds), yet few enough that
/// the disk `collect` checks for before it starts (220 kB a sample: 1.1 GB) is free on
/// any test machine.
const LONG_RUN: &str = "5000";

/// Start `softtouch collect ARGS` in `dir` and wait until `run` has `at_least` samples.
fn collect_until(dir: &Path, args: &[&str], at_least: i64) -> std::process::Child {
    let mut child = common::command(dir)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("{e}"));
    while count_samples(&dir.join("softtouch.db"), 1) < at_least {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("collect ended early: {status}");
        }
        std::thread::yield_now();
    }
    child
}

#[test]
fn sigterm_finishes_the_sample_retreats_and_stops_the_run() {
    let dir = tempdir();
    let child = collect_until(
        dir.path(),
        &["collect", "--samples", LONG_RUN, "--seed", "8"],
        3,
    );
    common::signal(&child, "TERM");
    let out = child.wait_with_output().unwrap_or_else(|e| panic!("{e}"));
    assert!(
        out.status.success(),
        "exit {:?}: {}",
        out.status.code(),
        text(&out.stderr)
    );
    assert!(
        text(&out.stdout).contains("stopped (resume with --resume 1)"),
        "{}",
        text(&out.stdout)
    );
    assert!(
        text(&out.stderr).contains("SIGTERM"),
        "{}",
        text(&out.stderr)
    );
    let s = stored(&dir.path().join("softtouch.db"), 1);
    assert_eq!(s.status, "stopped");
    assert_eq!(s.kinds("stopped").len(), 1);
    assert!(
        s.kinds("interrupted").is_empty(),
        "one signal lets the sample finish"
    );
    let n = s.samples.len();
    assert!(n >= 3);
    assert_eq!(s.indices(), plan_prefix(8, LONG_RUN, n), "no gap");
    assert!(!s.lease_held);
}

/// The first `n` indices a default run of `samples` samples with `seed` visits (the
/// default scene's five rods in equal blocks, each in its planned order), sorted.
fn plan_prefix(seed: u64, samples: &str, n: usize) -> Vec<u64> {
    use softtouch_collector::collect::{route, sampler};
    let samples: u64 = samples.parse().unwrap_or_else(|e| panic!("{e}"));
    let scene = softtouch_schemas::defaults::scene();
    let rods: Vec<String> = scene.rods.iter().map(|r| r.name.clone()).collect();
    let block = samples.div_ceil(rods.len() as u64);
    let schedule = sampler::RodSchedule::new(rods, block).unwrap_or_else(|| panic!("rods"));
    let poses = sampler::PoseSampler::new(seed, scene.poses.clone());
    let order = softtouch_schemas::rig::VisitOrder::Planned;
    let mut first: Vec<u64> =
        route::visits(order, &poses, &scene.poses, &schedule, samples, 0..samples)
            .into_iter()
            .flat_map(|v| v.todo)
            .take(n)
            .collect();
    first.sort_unstable();
    first
}

#[test]
fn a_second_process_is_refused_a_leased_run_and_takes_it_over_once_the_holder_is_gone() {
    let dir = tempdir();
    let mut child = collect_until(
        dir.path(),
        &["collect", "--samples", LONG_RUN, "--seed", "9"],
        2,
    );
    let holder = child.id();
    let refused = softtouch(dir.path(), &["collect", "--resume", "1"]);
    common::fails_with(&refused, 1, &format!("being collected by process {holder}"));
    assert!(
        count_samples(&dir.path().join("softtouch.db"), 1) >= 2,
        "the holder goes on"
    );

    // The holder dies without a word (kill -9): its lease goes stale with it.
    let _ = child.kill();
    let _ = child.wait();
    let db = dir.path().join("softtouch.db");
    let before = stored(&db, 1);
    assert!(before.lease_held && before.status == "running");
    let committed = before.indices();
    // Shrink the run so that the takeover finishes quickly.
    let planned = committed.len() as i64 + 3;
    runtime().block_on(async {
        let store = common::open_store(&db).await;
        sqlx::query(
            store
                .dialect()
                .sql("UPDATE runs SET samples_planned = ? WHERE run_id = 1"),
        )
        .bind(planned)
        .execute(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        store.close().await;
    });
    let out = softtouch(dir.path(), &["collect", "--resume", "1"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let s = stored(&db, 1);
    let taken = s.kinds("lease_taken_over");
    assert_eq!(taken.len(), 1, "{:?}", s.events);
    assert!(
        taken[0].contains(&format!("process {holder}")) && taken[0].contains("no longer running")
    );
    assert_eq!(s.status, "completed");
    // Every planned index is there (the holder's, taken in the plan's order, may lie
    // beyond the shrunk count).
    let all: Vec<u64> = (0..u64::try_from(planned).unwrap_or(0)).collect();
    let got = s.indices();
    assert!(all.iter().all(|i| got.contains(i)), "{got:?}");
    assert!(
        committed.iter().all(|i| s.indices().contains(i)),
        "no committed sample lost"
    );
    assert!(!s.lease_held);
}

#[test]
fn a_live_lease_refuses_a_resume_in_the_same_api() {
    let dir = tempdir();
    let store = SyncStore::open(common::target_of(&dir.path().join("t.db")))
        .unwrap_or_else(|e| panic!("{e}"));
    let plan = CollectPlan::new_run(
        &store,
        &NewRunRequest {
            samples: 2,
            seed: Some(1),
            ..NewRunRequest::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    match CollectPlan::resume(&store, plan.run_id) {
        Err(PlanError::Store(StoreError::Leased { run_id, holder })) => {
            assert_eq!(run_id, plan.run_id);
            assert_eq!(holder.pid, i64::from(std::process::id()));
        }
        other => panic!("expected a refusal, got {other:?}"),
    }
    store.close();
}

#[test]
fn a_lease_from_another_host_is_taken_over_only_once_its_heartbeat_is_stale() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    let out = softtouch(
        dir.path(),
        &["--db", "t.db", "collect", "--samples", "2", "--seed", "6"],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let lease = |age_s: u32| {
        runtime().block_on(async {
            let store = common::open_store(&db).await;
            sqlx::query(store.dialect().sql("UPDATE runs SET status = 'stopped', samples_planned = 3 WHERE run_id = 1"))
                .execute(store.pool())
                .await
                .unwrap_or_else(|e| panic!("{e}"));
            let backdated = if store.dialect() == softtouch_collector::store::Dialect::Postgres {
                sqlx::query(
                    "INSERT INTO run_leases (run_id, holder, pid, host, acquired_at, heartbeat_at)
                     VALUES (1, 'elsewhere', 4242, 'another-host',
                             to_char(clock_timestamp() AT TIME ZONE 'UTC' - make_interval(secs => $1),
                                     'YYYY-MM-DD\"T\"HH24:MI:SS.MS\"Z\"'),
                             to_char(clock_timestamp() AT TIME ZONE 'UTC' - make_interval(secs => $1),
                                     'YYYY-MM-DD\"T\"HH24:MI:SS.MS\"Z\"'))
                     ON CONFLICT (run_id) DO UPDATE SET holder = excluded.holder, pid = excluded.pid,
                         host = excluded.host, acquired_at = excluded.acquired_at,
                         heartbeat_at = excluded.heartbeat_at",
                )
                .bind(f64::from(age_s))
            } else {
                sqlx::query(
                    "INSERT OR REPLACE INTO run_leases (run_id, holder, pid, host, acquired_at, heartbeat_at)
                     VALUES (1, 'elsewhere', 4242, 'another-host',
                             strftime('%Y-%m-%dT%H:%M:%fZ', 'now', ?1),
                             strftime('%Y-%m-%dT%H:%M:%fZ', 'now', ?1))",
                )
                .bind(format!("-{age_s} seconds"))
            };
            backdated
            .execute(store.pool())
            .await
            .unwrap_or_else(|e| panic!("{e}"));
            store.close().await;
        });
    };
    // Fresh: its process may well be alive over there.
    lease(30);
    let out = softtouch(dir.path(), &["--db", "t.db", "collect", "--resume", "1"]);
    common::fails_with(
        &out,
        1,
        "being collected by process 4242 on host `another-host`",
    );
    // Silent for longer than LEASE_STALE_S: taken over.
    lease(3600);
    let out = softtouch(dir.path(), &["--db", "t.db", "collect", "--resume", "1"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("1 ok, 0 rejected, 0 already present"),
        "{}",
        text(&out.stdout)
    );
    let s = stored(&db, 1);
    let taken = s.kinds("lease_taken_over");
    assert_eq!(taken.len(), 1);
    assert!(taken[0].contains("no heartbeat for 3600 s"), "{taken:?}");
    assert_eq!(s.status, "completed");
    assert_eq!(s.indices(), [0, 1, 2]);
}

#[test]
fn sighup_then_a_second_signal_stops_the_binary_at_once() {
    let dir = tempdir();
    let child = collect_until(
        dir.path(),
        &["collect", "--samples", LONG_RUN, "--seed", "10"],
        2,
    );
    // Both signals are queued while the child is stopped, and arrive together when it
    // continues. Sent to a running child, even microseconds apart from one shell, a
    // descheduled shell let the child finish its sample and exit between them (a
    // simulated sample takes about a millisecond).
    let pid = child.id();
    let ok = Command::new("sh")
        .args([
            "-c",
            &format!("kill -STOP {pid} && kill -HUP {pid} && kill -TERM {pid} && kill -CONT {pid}"),
        ])
        .status()
        .unwrap_or_else(|e| panic!("sh: {e}"))
        .success();
    assert!(ok, "kill -STOP, -HUP, -TERM, -CONT failed");
    let out = child.wait_with_output().unwrap_or_else(|e| panic!("{e}"));
    assert!(
        out.status.success(),
        "exit {:?}: {}",
        out.status.code(),
        text(&out.stderr)
    );
    let err = text(&out.stderr);
    assert!(
        err.contains("SIGHUP") && err.contains("stopping the arm now"),
        "{err}"
    );
    let s = stored(&dir.path().join("softtouch.db"), 1);
    assert_eq!(s.status, "stopped");
    let interrupted = s.kinds("interrupted");
    assert_eq!(interrupted.len(), 1, "{:?}", s.events);
    assert!(interrupted[0].contains("not sent home"));
    let n = s.samples.len();
    assert_eq!(s.indices(), plan_prefix(10, LONG_RUN, n), "no gap");
    assert!(!s.lease_held);
}

#[test]
fn a_frame_not_covered_by_readings_within_the_skew_limit_is_rejected_as_clock_skew() {
    let dir = tempdir();
    let db = dir.path().join("t.db");
    // 119 fps frames against 1 kHz readings: with a 1 µs limit (below what the rig's
    // validation accepts, set on the plan) a frame has a reading that close on both
    // sides only once in 119 frames, as when camera and sensor stamps drift apart.
    // (At 120 fps every third frame falls on a reading, and where it falls depends on
    // how long each approach takes.)
    let e = faulty_run(
        &db,
        4,
        Faults {
            edit_plan: |p| {
                p.rig.procedure.max_skew_s = Some(1e-6);
                if let softtouch_schemas::rig::CameraDevice::Sim { fps } = &mut p.rig.camera {
                    *fps = 119.0;
                }
            },
            ..Faults::default()
        },
    );
    let s = stored(&db, e.run_id);
    assert_eq!(e.outcome, Outcome::Completed);
    let skewed = s.kinds("clock_skew");
    assert!(!skewed.is_empty(), "{:?}", s.events);
    let rejected: Vec<_> = s.samples.iter().filter(|x| x.1 == "rejected").collect();
    assert!(!rejected.is_empty(), "{:?}", s.samples);
    for x in &rejected {
        assert_eq!(x.2.as_deref(), Some("clock_skew"), "{x:?}");
        assert_eq!(x.3, 3, "retried to the attempt limit: {x:?}");
    }
    assert!(e.at_home() && e.still());
    nothing_lost(&e, &s);
}
