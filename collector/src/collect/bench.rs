//! Benchmarks of collection: what accuracy costs in time, where the time goes, and
//! how fast the store ingests.
//!
//! Device time is measured as the time spent *executing* device code (each poll of a
//! device future is timed), not the time a future is pending, so a device waiting on
//! the clock while the job works is not counted twice.

use super::rods::RodChanger;
use super::{CollectDevices, CollectPlan, Counters, Progress, collect, sampler::RodSchedule};
use crate::store::{OwnedNewRun, StoreError, SyncStore, WriterStats};
use async_trait::async_trait;
use softtouch_drivers::{
    Arm, ArmState, Camera, Clock as _, DeviceError, ForceSensor, Frame, TokioClock,
};
use softtouch_schemas::config::to_toml;
use softtouch_schemas::{ArmPose, ContactPose, FtReading, RigConfig, SceneSpec, TimestampNs};
use softtouch_sim::{SceneSim, SimRig};
use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};

/// Accumulates the time spent polling device futures.
#[derive(Debug, Clone, Default)]
pub struct DeviceTimer(Arc<AtomicU64>);

impl DeviceTimer {
    /// Total time spent in device code.
    #[must_use]
    pub fn total(&self) -> Duration {
        Duration::from_nanos(self.0.load(Ordering::Relaxed))
    }

    async fn time<T>(&self, fut: impl Future<Output = T> + Send) -> T {
        PollTimed {
            inner: Box::pin(fut),
            acc: &self.0,
        }
        .await
    }
}

struct PollTimed<'a, T> {
    inner: Pin<Box<dyn Future<Output = T> + Send + 'a>>,
    acc: &'a AtomicU64,
}

impl<T> Future for PollTimed<'_, T> {
    type Output = T;
    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<T> {
        let started = Instant::now();
        let out = self.inner.as_mut().poll(cx);
        let ns = u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX);
        self.acc.fetch_add(ns, Ordering::Relaxed);
        out
    }
}

struct Timed<D> {
    inner: D,
    timer: DeviceTimer,
}

#[async_trait]
impl Arm for Timed<Box<dyn Arm>> {
    async fn move_to(&mut self, target: &ArmPose, speed_m_s: f64) -> Result<ArmState, DeviceError> {
        let timer = self.timer.clone();
        timer.time(self.inner.move_to(target, speed_m_s)).await
    }
    async fn move_through(
        &mut self,
        legs: &[(ArmPose, f64)],
    ) -> Result<(ArmState, Vec<TimestampNs>), DeviceError> {
        let timer = self.timer.clone();
        timer.time(self.inner.move_through(legs)).await
    }
    async fn state(&mut self) -> Result<ArmState, DeviceError> {
        let timer = self.timer.clone();
        timer.time(self.inner.state()).await
    }
    async fn recover(&mut self) -> Result<(), DeviceError> {
        let timer = self.timer.clone();
        timer.time(self.inner.recover()).await
    }
    async fn stop(&mut self) -> Result<(), DeviceError> {
        let timer = self.timer.clone();
        timer.time(self.inner.stop()).await
    }
    async fn joints_rad(&mut self) -> Result<Option<[f64; 7]>, DeviceError> {
        let timer = self.timer.clone();
        timer.time(self.inner.joints_rad()).await
    }
    async fn move_joints(&mut self, q_rad: &[f64; 7]) -> Result<Option<ArmState>, DeviceError> {
        let timer = self.timer.clone();
        timer.time(self.inner.move_joints(q_rad)).await
    }
    fn pose_feed(&self) -> Option<softtouch_drivers::PoseFeed> {
        self.inner.pose_feed()
    }
    fn found_at_connect(&self) -> Option<String> {
        self.inner.found_at_connect()
    }
}

#[async_trait]
impl ForceSensor for Timed<Box<dyn ForceSensor>> {
    async fn start(&mut self) -> Result<(), DeviceError> {
        let timer = self.timer.clone();
        timer.time(self.inner.start()).await
    }
    async fn read(&mut self, out: &mut Vec<FtReading>) -> Result<usize, DeviceError> {
        let timer = self.timer.clone();
        timer.time(self.inner.read(out)).await
    }
    async fn bias(&mut self) -> Result<(), DeviceError> {
        let timer = self.timer.clone();
        timer.time(self.inner.bias()).await
    }
    async fn stop(&mut self) -> Result<(), DeviceError> {
        let timer = self.timer.clone();
        timer.time(self.inner.stop()).await
    }
    fn lost_readings(&self) -> u64 {
        self.inner.lost_readings()
    }
}

#[async_trait]
impl Camera for Timed<Box<dyn Camera>> {
    async fn frame_after(&mut self, t: TimestampNs, timeout_ms: u64) -> Result<Frame, DeviceError> {
        let timer = self.timer.clone();
        timer.time(self.inner.frame_after(t, timeout_ms)).await
    }
    fn dropped_frames(&self) -> u64 {
        self.inner.dropped_frames()
    }
}

/// Per-sample wall time and the device time inside it.
#[derive(Debug, Default)]
struct Recorder {
    timer: DeviceTimer,
    last_wall: Option<Instant>,
    last_device: Duration,
    samples: Vec<(Duration, Duration)>,
}

impl Progress for Recorder {
    fn sample_done(&mut self, _index: u64, _c: &Counters) {
        let now = Instant::now();
        let device = self.timer.total();
        if let Some(last) = self.last_wall {
            self.samples
                .push((now - last, device.saturating_sub(self.last_device)));
        }
        self.last_wall = Some(now);
        self.last_device = device;
    }
    fn note(&mut self, _message: &str) {}
}

/// One point of the sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepPoint {
    /// Settle time, s (with a signal-ended settle, its bound).
    pub settle_s: f64,
    /// What ended the settle (the rig's `procedure.settle_end`).
    pub settle_end: softtouch_schemas::rig::SettleEnd,
    /// The settle as it ran, mean per sample, s (with a fixed settle, `settle_s` and
    /// the read of the arm's pose).
    pub mean_settle_s: f64,
    /// Window length, s.
    pub window_s: f64,
    /// Samples taken.
    pub samples: u64,
    /// Samples accepted.
    pub accepted: u64,
    /// RMS error of the force label against the equilibrium truth, N (all axes).
    pub force_rmse_n: f64,
    /// RMS error of the torque label, N·mm (all axes).
    pub torque_rmse_nmm: f64,
    /// Samples per hour on the rig's clock.
    pub samples_per_hour: f64,
    /// Wall time of the point, s.
    pub wall_s: f64,
}

impl SweepPoint {
    /// The point in one line, as the sweep prints it while it runs.
    #[must_use]
    pub fn line(&self) -> String {
        format!(
            "settle {} {} s (mean {:.3} s), window {} s: {:.4} N, {:.2} N·mm, {:.0} samples/h",
            self.settle_end.as_str(),
            self.settle_s,
            self.mean_settle_s,
            self.window_s,
            self.force_rmse_n,
            self.torque_rmse_nmm,
            self.samples_per_hour
        )
    }
}

/// Where a sample's time went.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Breakdown {
    /// Samples measured.
    pub samples: usize,
    /// Median wall time per sample on the job's thread, ms.
    pub wall_ms: f64,
    /// Median time in device code (simulation: physics, rendering, streams), ms.
    pub device_ms: f64,
    /// Median of everything else on the job's thread (orchestration, hand-off), ms.
    pub orchestration_ms: f64,
    /// 95th percentile of that, ms.
    pub orchestration_p95_ms: f64,
    /// Writer thread: encoding per sample, ms (mean, on the other core).
    pub encode_ms: f64,
    /// Writer thread: database per sample, ms (mean, on the other core).
    pub write_ms: f64,
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

/// The benchmark failed.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// The store failed.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// Collection failed.
    #[error(transparent)]
    Collect(#[from] super::CollectError),
    /// The simulator refused the rig or scene.
    #[error("simulator: {0}")]
    Sim(String),
    /// A result file could not be written or drawn (the message names it).
    #[error("{0}")]
    Output(String),
}

struct NoRods;

#[async_trait]
impl RodChanger for NoRods {
    async fn change_rod(&mut self, _rod: &str) -> Result<(), DeviceError> {
        Ok(())
    }
}

/// The sweep: each fixed settle time at each window, then the settle ended by the
/// signal (bounded by the rig's `settle_s`) at each window, `samples` samples a point
/// ([`sweep_point`]); `on_point` sees each point as it is measured. What the time a
/// signal-ended settle saves costs in accuracy.
///
/// # Errors
/// As [`sweep_point`].
pub async fn sweep(
    store: &SyncStore,
    rig: &RigConfig,
    scene: &SceneSpec,
    seed: u64,
    (settle_s, window_s): (&[f64], &[f64]),
    samples: u64,
    mut on_point: impl FnMut(&SweepPoint),
) -> Result<Vec<SweepPoint>, BenchError> {
    use softtouch_schemas::rig::SettleEnd;
    let with = |end: SettleEnd| {
        let mut r = rig.clone();
        r.procedure.settle_end = end;
        r
    };
    let (fixed, signal) = (with(SettleEnd::Fixed), with(SettleEnd::Signal));
    let mut cases: Vec<(&RigConfig, f64, f64)> = Vec::new();
    for &s in settle_s {
        cases.extend(window_s.iter().map(|&w| (&fixed, s, w)));
    }
    cases.extend(
        window_s
            .iter()
            .map(|&w| (&signal, rig.procedure.settle_s, w)),
    );
    let mut points = Vec::new();
    for (rig, s, w) in cases {
        let (p, _) = sweep_point(store, rig, scene, seed, s, w, samples).await?;
        on_point(&p);
        points.push(p);
    }
    Ok(points)
}

/// Run `samples` samples with `settle_s` and `window_s` on the simulated rig (virtual
/// time: the runtime must be paused), and measure label error against the truth.
pub async fn sweep_point(
    store: &SyncStore,
    rig: &RigConfig,
    scene: &SceneSpec,
    seed: u64,
    settle_s: f64,
    window_s: f64,
    samples: u64,
) -> Result<(SweepPoint, Breakdown), BenchError> {
    let mut rig = rig.clone();
    rig.procedure.settle_s = settle_s;
    let plan_settle_end = rig.procedure.settle_end;
    rig.procedure.ft_window_s = window_s;
    let rate_hz = match rig.force_sensor {
        softtouch_schemas::ForceSensorDevice::Sim { rate_hz } => rate_hz,
        _ => {
            return Err(BenchError::Sim(
                "the benchmark runs on the simulated rig only".into(),
            ));
        }
    };
    // Accept a window with 80 % of its expected readings.
    rig.procedure.min_window_readings = ((rate_hz * window_s * 0.8).floor() as u32).max(1);
    let rod = scene
        .rods
        .first()
        .map(|r| r.name.clone())
        .unwrap_or_default();
    let run_id = store.create_run(OwnedNewRun {
        seed,
        samples_planned: samples,
        rod_schedule: vec![rod.clone()],
        rod_block: samples.max(1),
        scene_name: format!(
            "{} (bench settle {} {settle_s} s, window {window_s} s)",
            scene.name,
            plan_settle_end.as_str()
        ),
        medium: scene.medium,
        rig_toml: to_toml(&rig),
        scene_toml: to_toml(scene),
        poses_from: None,
    })?;
    let clock = TokioClock::new();
    let sim = SimRig::new(&rig, scene, seed, clock).map_err(|e| BenchError::Sim(e.to_string()))?;
    let (arm, force_sensor, camera, _gripper, _handle) = sim.into_boxed();
    let timer = DeviceTimer::default();
    let devices = CollectDevices {
        arm: Box::new(Timed {
            inner: arm,
            timer: timer.clone(),
        }),
        force_sensor: Box::new(Timed {
            inner: force_sensor,
            timer: timer.clone(),
        }),
        camera: Box::new(Timed {
            inner: camera,
            timer: timer.clone(),
        }),
        rods: Box::new(NoRods),
    };
    let plan = CollectPlan {
        run_id,
        seed,
        start_index: 0,
        end_index: samples,
        gaps: Vec::new(),
        lease: None,
        rods: RodSchedule::new(vec![rod], samples.max(1))
            .ok_or_else(|| BenchError::Sim("no rod".into()))?,
        rig,
        scene: scene.clone(),
    };
    let before: WriterStats = store.flush()?;
    let (_stop_tx, stop_rx) = tokio::sync::watch::channel(0u32);
    let mut recorder = Recorder {
        timer,
        ..Recorder::default()
    };
    let started = Instant::now();
    let t0 = clock.now();
    let (_, counters) = collect(store, &plan, devices, clock, stop_rx, &mut recorder).await;
    let virtual_s = clock.now().as_secs_f64() - t0.as_secs_f64();
    let after = store.flush()?;
    let wall_s = started.elapsed().as_secs_f64();

    let truth = SceneSim::new(scene, seed).map_err(|e| BenchError::Sim(e.to_string()))?;
    let (mut f2, mut t2, mut n) = (0.0, 0.0, 0u64);
    for row in store.labels(run_id)?.iter().filter(|r| r.status == "ok") {
        let pose = ContactPose {
            x_m: row.cmd_x_m,
            z_m: row.cmd_z_m,
            theta_rad: row.cmd_theta_rad,
        };
        let w = truth
            .wrench(&row.rod, &pose)
            .map_err(|e| BenchError::Sim(e.to_string()))?;
        let got = [
            row.wrench.fx_n,
            row.wrench.fy_n,
            row.wrench.fz_n,
            row.wrench.tx_nm,
            row.wrench.ty_nm,
            row.wrench.tz_nm,
        ];
        let want = w.to_array();
        for i in 0..3 {
            f2 += (got[i] - want[i]).powi(2);
            t2 += ((got[i + 3] - want[i + 3]) * 1000.0).powi(2);
        }
        n += 1;
    }
    let per = |x: f64| {
        if n > 0 {
            (x / (3 * n) as f64).sqrt()
        } else {
            f64::NAN
        }
    };
    let point = SweepPoint {
        settle_s,
        settle_end: plan_settle_end,
        mean_settle_s: if counters.phases.samples > 0 {
            counters.phases.settle_ns as f64 * 1e-9 / counters.phases.samples as f64
        } else {
            f64::NAN
        },
        window_s,
        samples,
        accepted: counters.ok,
        force_rmse_n: per(f2),
        torque_rmse_nmm: per(t2),
        samples_per_hour: if virtual_s > 0.0 {
            samples as f64 / virtual_s * 3600.0
        } else {
            f64::NAN
        },
        wall_s,
    };

    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let mut wall: Vec<f64> = recorder.samples.iter().map(|(w, _)| ms(*w)).collect();
    let mut device: Vec<f64> = recorder.samples.iter().map(|(_, d)| ms(*d)).collect();
    let mut orch: Vec<f64> = recorder
        .samples
        .iter()
        .map(|(w, d)| ms(w.saturating_sub(*d)))
        .collect();
    for v in [&mut wall, &mut device, &mut orch] {
        v.sort_by(f64::total_cmp);
    }
    let written = (after.inserted - before.inserted).max(1) as f64;
    let breakdown = Breakdown {
        samples: recorder.samples.len(),
        wall_ms: quantile(&wall, 0.5),
        device_ms: quantile(&device, 0.5),
        orchestration_ms: quantile(&orch, 0.5),
        orchestration_p95_ms: quantile(&orch, 0.95),
        encode_ms: ms(after.encode.saturating_sub(before.encode)) / written,
        write_ms: ms(after.write.saturating_sub(before.write)) / written,
    };
    Ok((point, breakdown))
}
