//! `softtouch live`'s session: the model's estimate at camera rate beside the
//! force/torque sensor, paired frame by frame, while a scripted press runs (home,
//! approach, press in, hold, out, home; every move workspace-checked, every reading
//! through the one force guard). The verb builds the devices, runs a `Session` and
//! stops the arm on every exit.

use std::collections::VecDeque;
use std::io::Write;
use std::time::Duration;

use softtouch_drivers::{
    Arm, Camera, Clock, DeviceError, ForceGuard, ForceSensor, Frame, GuardTrip,
};
use softtouch_grasp::ForceEstimator;
use softtouch_schemas::{ArmPose, ContactPose, FtReading, RigConfig, TimestampNs, Wrench};

/// Time the hold at depth lasts, s.
pub const HOLD_S: f64 = 1.0;
/// Time watched after the script ends, s.
pub const TAIL_S: f64 = 0.5;
/// A frame waits at most this long for a sensor reading at or after its exposure, ns.
const PAIR_WAIT_NS: u64 = 100_000_000;

/// When watching ends.
#[derive(Debug, Clone, Copy)]
pub enum Until {
    /// After this long.
    For(Duration),
    /// `tail` after the script ends; an error if it has not ended after `limit`.
    ScriptDone { tail: Duration, limit: Duration },
}
/// Readings kept for pairing with frames, ns.
const KEEP_NS: u64 = 500_000_000;

/// One press: waypoints in the rod frame with their speeds, and pauses.
#[derive(Debug, Clone, Copy)]
pub enum Step {
    Move(ContactPose, f64),
    Hold(Duration),
}

/// The scripted press: home, approach to first contact, press in slowly, hold, out,
/// home. Checked against the workspace before anything moves.
pub fn press_script(rig: &RigConfig, depth_m: f64) -> Result<Vec<Step>, String> {
    let w = &rig.workspace;
    let fast = rig.procedure.approach_speed_m_s;
    let slow = (fast / 4.0).max(1e-3);
    let at = |x_m: f64| ContactPose {
        x_m,
        z_m: 0.0,
        theta_rad: 0.0,
    };
    let steps = vec![
        Step::Move(w.home, fast),
        Step::Move(at(0.0), fast),
        Step::Move(at(depth_m), slow),
        Step::Hold(Duration::from_secs_f64(HOLD_S)),
        Step::Move(at(0.0), slow),
        Step::Move(w.home, fast),
    ];
    for (i, s) in steps.iter().enumerate() {
        if let Step::Move(p, _) = s {
            // Home is the collection's safe pose, clear of the rod: only the flange's
            // reach applies to it; the contact poses must lie in the contact box too.
            let home = i == 0 || i + 1 == steps.len();
            let target = ArmPose::from_contact(&w.base_from_rod, p);
            if !p.is_finite() || (!home && !w.contains_contact(p)) || !w.contains_arm(&target) {
                return Err(format!(
                    "the press to x = {:.4} m (--depth-m {depth_m}) lies outside the rig's workspace (workspace x_m [{}, {}] m, flange at [{:.4}, {:.4}, {:.4}] m)",
                    p.x_m,
                    w.x_m.min,
                    w.x_m.max,
                    target.translation_m[0],
                    target.translation_m[1],
                    target.translation_m[2]
                ));
            }
        }
    }
    Ok(steps)
}

/// Length of the script, s (moves at their speed along x; home to contact straight).
pub fn script_s(rig: &RigConfig, steps: &[Step]) -> f64 {
    let mut x = rig.workspace.home.x_m;
    let mut s = 0.0;
    for step in steps {
        match step {
            Step::Move(p, v) => {
                s += (p.x_m - x).abs() / v + 0.2;
                x = p.x_m;
            }
            Step::Hold(d) => s += d.as_secs_f64(),
        }
    }
    s
}

async fn run_script(arm: &mut dyn Arm, rig: &RigConfig, steps: &[Step]) -> Result<(), String> {
    for step in steps {
        match step {
            Step::Move(p, v) => {
                let target = ArmPose::from_contact(&rig.workspace.base_from_rod, p);
                arm.move_to(&target, *v)
                    .await
                    .map_err(|e| format!("arm move to x = {:.4} m: {e}", p.x_m))?;
            }
            Step::Hold(d) => tokio::time::sleep(*d).await,
        }
    }
    Ok(())
}

/// One row of the CSV.
#[derive(Debug, Clone, Copy)]
struct Row {
    t_s: f64,
    frame: u64,
    estimate: Option<Wrench>,
    sensor: Option<Wrench>,
}

/// The reading nearest `t`: how far from it, ns, and its wrench.
fn nearest(readings: &VecDeque<FtReading>, t: TimestampNs) -> Option<(u64, Wrench)> {
    readings
        .iter()
        .min_by_key(|r| r.t.0.abs_diff(t.0))
        .map(|r| (r.t.0.abs_diff(t.0), r.wrench_in_sensor))
}

fn axes(w: Option<Wrench>) -> [f64; 6] {
    w.map_or([f64::NAN; 6], |w| {
        [
            w.force_n[0],
            w.force_n[1],
            w.force_n[2],
            w.torque_nm[0],
            w.torque_nm[1],
            w.torque_nm[2],
        ]
    })
}

/// One live session: the rig, the press script and when to stop.
pub struct Session<'a> {
    pub rig: &'a RigConfig,
    pub steps: &'a [Step],
    pub until: Until,
    pub every: u64,
    pub frame_timeout_ms: u64,
    pub clock: &'a dyn Clock,
    /// A signal's stop request: the session ends there and the arm is stopped.
    pub stop: softtouch_collector::stop::StopRequest,
}

impl std::fmt::Debug for Session<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Session")
            .field("steps", &self.steps.len())
            .field("until", &self.until)
            .field("every", &self.every)
            .field("frame_timeout_ms", &self.frame_timeout_ms)
            .finish_non_exhaustive()
    }
}

#[derive(Debug, Default)]
pub struct Summary {
    frames: u64,
    no_estimate: u64,
    first_t_s: Option<f64>,
    last_t_s: f64,
    /// Sums of squared estimate − sensor per axis, and the count.
    sq: [f64; 6],
    paired: u64,
    /// Largest force magnitude the sensor read, N (the press is along x, not z).
    peak_sensor_force_n: f64,
    script_done: bool,
}

impl Summary {
    fn add(&mut self, row: &Row) {
        self.frames += 1;
        self.first_t_s.get_or_insert(row.t_s);
        self.last_t_s = row.t_s;
        if let (Some(e), Some(s)) = (row.estimate, row.sensor) {
            let (e, s) = (axes(Some(e)), axes(Some(s)));
            for i in 0..6 {
                self.sq[i] += (e[i] - s[i]).powi(2);
            }
            self.paired += 1;
        }
        if row.estimate.is_none() {
            self.no_estimate += 1;
        }
        if let Some(s) = row.sensor {
            self.peak_sensor_force_n = self.peak_sensor_force_n.max(s.force_norm_n());
        }
    }

    pub fn print(&self, out: &mut dyn Write) -> std::io::Result<()> {
        let span = self.last_t_s - self.first_t_s.unwrap_or(self.last_t_s);
        let rate = if span > 0.0 {
            (self.frames.saturating_sub(1)) as f64 / span
        } else {
            0.0
        };
        // Torques in N·mm, as every line before this one prints them.
        let rms: Vec<String> = self
            .sq
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let unit = if i < 3 { 1.0 } else { 1000.0 };
                format!("{:.3}", unit * (s / self.paired.max(1) as f64).sqrt())
            })
            .collect();
        writeln!(
            out,
            "{} frames at {rate:.1} Hz over {span:.1} s (the rig's clock), {} without an estimate, script {}; peak |F| on the sensor {:.3} N",
            self.frames,
            self.no_estimate,
            if self.script_done {
                "done"
            } else {
                "not run to the end"
            },
            self.peak_sensor_force_n
        )?;
        writeln!(
            out,
            "RMS estimate − sensor over {} frames: Fx Fy Fz {} {} {} N, Tx Ty Tz {} {} {} N·mm",
            self.paired, rms[0], rms[1], rms[2], rms[3], rms[4], rms[5]
        )
    }
}

/// A frame's estimate waiting for the sensor readings around its exposure.
#[derive(Debug, Clone, Copy)]
struct Pending {
    t: TimestampNs,
    frame: u64,
    estimate: Option<Wrench>,
}

/// Writes the rows and lines of frames and keeps the summary.
struct Output<'a> {
    csv: &'a mut dyn Write,
    out: &'a mut dyn Write,
    every: u64,
    start: TimestampNs,
    summary: Summary,
}

impl Output<'_> {
    fn emit(&mut self, p: Pending, sensor: Option<Wrench>) -> Result<(), String> {
        let row = Row {
            t_s: p.t.0.saturating_sub(self.start.0) as f64 * 1e-9,
            frame: p.frame,
            estimate: p.estimate,
            sensor,
        };
        let (e, s) = (axes(row.estimate), axes(row.sensor));
        // Torques in N·mm, as the terminal, the report and every other CSV give them.
        let in_csv = |a: &[f64; 6]| {
            let mut a = *a;
            for v in &mut a[3..] {
                *v *= 1000.0;
            }
            a
        };
        let (e_csv, s_csv) = (in_csv(&e), in_csv(&s));
        let cell = |v: f64| {
            if v.is_finite() {
                format!("{v}")
            } else {
                String::new()
            }
        };
        let cells: Vec<String> = e_csv.iter().chain(s_csv.iter()).map(|v| cell(*v)).collect();
        writeln!(self.csv, "{},{},{}", row.t_s, row.frame, cells.join(","))
            .map_err(|e| format!("cannot write the CSV: {e}"))?;
        if self.summary.frames.is_multiple_of(self.every) {
            let f = |v: f64| {
                if v.is_finite() {
                    format!("{v:+6.2}")
                } else {
                    "   -  ".into()
                }
            };
            writeln!(
                self.out,
                "t {:6.2} s  model F {} {} {} N  sensor F {} {} {} N  model Tz {} sensor Tz {} N·mm",
                row.t_s,
                f(e[0]),
                f(e[1]),
                f(e[2]),
                f(s[0]),
                f(s[1]),
                f(s[2]),
                f(e[5] * 1000.0),
                f(s[5] * 1000.0)
            )
            .map_err(|e| format!("cannot write output: {e}"))?;
        }
        self.summary.add(&row);
        Ok(())
    }
}

impl Session<'_> {
    /// Frames, sensor and script run side by side: a frame's estimate is computed when
    /// it arrives and written once the sensor has delivered a reading at or after its
    /// exposure (the readings come in packets), paired with the nearest reading.
    pub async fn run(
        &self,
        arm: &mut dyn Arm,
        sensor: &mut dyn ForceSensor,
        camera: &mut dyn Camera,
        predictor: &mut softtouch_trainer::Predictor,
        csv: &mut dyn Write,
        out: &mut dyn Write,
    ) -> Result<Summary, String> {
        writeln!(
            csv,
            "t_s,frame,est_fx_n,est_fy_n,est_fz_n,est_tx_nmm,est_ty_nmm,est_tz_nmm,ft_fx_n,ft_fy_n,ft_fz_n,ft_tx_nmm,ft_ty_nmm,ft_tz_nmm"
        )
        .map_err(|e| format!("cannot write the CSV: {e}"))?;
        sensor
            .start()
            .await
            .map_err(|e| format!("force/torque sensor: {e}"))?;
        let mut steps = self.steps;
        if let Some(Step::Move(home, v)) = steps.first() {
            // Home first, clear of the rod, then zero the sensor there.
            run_script(arm, self.rig, &[Step::Move(*home, *v)]).await?;
            sensor
                .bias()
                .await
                .map_err(|e| format!("force/torque sensor bias: {e}"))?;
            steps = &steps[1..];
        }
        let start = self.clock.now();
        let at = |d: Duration| TimestampNs(start.0.saturating_add(d.as_nanos() as u64));
        let mut script_done = steps.is_empty();
        let mut script_end: Option<TimestampNs> = script_done.then_some(start);
        let mut o = Output {
            csv,
            out,
            every: self.every,
            start,
            summary: Summary::default(),
        };
        let mut next_t = start;
        let mut readings: VecDeque<FtReading> = VecDeque::new();
        let mut pending: VecDeque<Pending> = VecDeque::new();
        let mut buf = Vec::new();
        // The one guard collection uses: every reading, every torque axis, a stale stream.
        let guard = ForceGuard {
            max_force_n: self.rig.limits.max_force_n,
            max_torque_nm: self.rig.limits.max_torque_nm,
            stale: Duration::from_secs_f64(self.rig.procedure.ft_stale_s),
        };
        let tripped = |t: GuardTrip| format!("force/torque guard: {t}");
        let mut last_reading = tokio::time::Instant::now();
        let script = run_script(arm, self.rig, steps);
        tokio::pin!(script);
        let stop = softtouch_collector::stop::requested(self.stop.clone());
        tokio::pin!(stop);
        loop {
            let now = self.clock.now();
            let done = match self.until {
                Until::For(d) => now >= at(d),
                Until::ScriptDone { tail, limit } => {
                    if !script_done && now >= at(limit) {
                        return Err(format!(
                            "the scripted press had not ended after {:.1} s",
                            limit.as_secs_f64()
                        ));
                    }
                    script_end.is_some_and(|e| now.0 >= e.0.saturating_add(tail.as_nanos() as u64))
                }
            };
            if done {
                break;
            }
            tokio::select! {
                name = &mut stop => return Err(format!("stopped by {name}")),
                finished = &mut script, if !script_done => {
                    finished?;
                    script_done = true;
                    script_end = Some(self.clock.now());
                }
                got = sensor.read(&mut buf) => {
                    if got.map_err(|e| format!("force/torque sensor: {e}"))? > 0 {
                        last_reading = tokio::time::Instant::now();
                    }
                    guard.check_all(&buf).map_err(tripped)?;
                    readings.extend(buf.drain(..));
                    let newest = readings.back().map_or(0, |r| r.t.0);
                    while readings
                        .front()
                        .is_some_and(|r| newest.saturating_sub(r.t.0) > KEEP_NS)
                    {
                        readings.pop_front();
                    }
                }
                () = tokio::time::sleep_until(last_reading + guard.stale) => {
                    guard.check_silence(last_reading.elapsed()).map_err(tripped)?;
                }
                frame = camera.frame_after(next_t, self.frame_timeout_ms) => {
                    let frame: Frame = frame.map_err(|e: DeviceError| format!("camera: {e}"))?;
                    next_t = TimestampNs(frame.meta.t.0 + 1);
                    let estimate = predictor
                        .estimate(&frame)
                        .map_err(|e| format!("model: {e}"))?
                        .filter(Wrench::is_finite);
                    pending.push_back(Pending {
                        t: frame.meta.t,
                        frame: frame.meta.sequence,
                        estimate,
                    });
                }
            }
            // Pair every frame whose exposure the readings have passed (or that waited
            // long enough: a stalled stream leaves its sensor columns empty).
            let newest = readings.back().map(|r| r.t.0);
            let now = self.clock.now().0;
            while let Some(p) = pending.front().copied() {
                let covered = newest.is_some_and(|n| n >= p.t.0);
                if !covered && now.saturating_sub(p.t.0) < PAIR_WAIT_NS {
                    break;
                }
                pending.pop_front();
                let near = nearest(&readings, p.t)
                    .filter(|(dt, _)| *dt <= PAIR_WAIT_NS)
                    .map(|(_, w)| w);
                o.emit(p, near)?;
            }
        }
        for p in pending {
            let near = nearest(&readings, p.t)
                .filter(|(dt, _)| *dt <= PAIR_WAIT_NS)
                .map(|(_, w)| w);
            o.emit(p, near)?;
        }
        o.summary.script_done = script_done;
        Ok(o.summary)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use softtouch_schemas::defaults;

    #[test]
    fn the_press_script_stays_in_the_workspace_or_is_refused() {
        let rig = defaults::rig();
        let steps = press_script(&rig, 0.03).expect("fits");
        assert_eq!(steps.len(), 6);
        assert!(script_s(&rig, &steps) > HOLD_S);
        let e = press_script(&rig, 0.5).expect_err("too deep");
        assert!(
            e.contains("--depth-m 0.5") && e.contains("workspace"),
            "{e}"
        );
        assert!(press_script(&rig, f64::NAN).is_err());
    }
}
