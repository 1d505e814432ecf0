//! A session's table: success per σ, scene, object and mode with Wilson 95 %
//! intervals and failure reasons, beside the paper's overall rates; its CSVs and
//! charts (Figure 4f, success against σ).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use softtouch_grasp::{FailReason, Mode, Z_95, wilson_interval};
use softtouch_schemas::Medium;

use super::{
    PAPER_SIGMA_MM, SceneSweep, TrialPlan, TrialsError, medium_name, paper_rate, sigma_label,
};
use crate::store::GraspTrialRow;
use softtouch_collector::plot::{BarChart, BarSeries, bar_chart};

/// One cell of the table: an object (or all of them) × mode × medium × σ.
#[derive(Debug, Clone, PartialEq)]
pub struct Cell {
    /// Which σ of the plan.
    pub sigma_index: u32,
    /// That σ, mm.
    pub sigma_mm: f64,
    /// Which scene of the session.
    pub scene_index: u32,
    /// The scene's medium.
    pub medium: Medium,
    /// `None`: every object together.
    pub object: Option<String>,
    /// Open or closed loop.
    pub mode: Mode,
    /// Trials stored.
    pub trials: u64,
    /// Of which held.
    pub held: u64,
    /// Wilson 95 % interval of the success rate.
    pub interval: [f64; 2],
    /// Failures per reason.
    pub reasons: BTreeMap<&'static str, u64>,
    /// The largest true grip force of its trials, N (`None` on a rig: no truth).
    pub peak_true_max_n: Option<f64>,
    /// The deepest closing past the calibrated touch of its trials, mm (what a rig
    /// shows of the grip; `None` where no trial kept it).
    pub past_touch_max_mm: Option<f64>,
}

impl Cell {
    /// The success rate, if any trial ran.
    #[must_use]
    pub fn rate(&self) -> Option<f64> {
        (self.trials > 0).then(|| self.held as f64 / self.trials as f64)
    }
    /// The grip at its firmest, as the tables print it: the largest true force where
    /// the simulator knows it, else the deepest closing past the calibrated touch.
    #[must_use]
    pub fn grip_text(&self) -> String {
        match (self.peak_true_max_n, self.past_touch_max_mm) {
            (Some(n), _) => format!("{n:.2} N"),
            (None, Some(mm)) => format!("{mm:.2} mm"),
            (None, None) => "–".to_owned(),
        }
    }
    /// The failures that happened, `reason n` joined by commas (`crush 2, slip 9`), as
    /// the terminal, the report and the sweep table print them.
    #[must_use]
    pub fn failures_text(&self) -> String {
        self.reasons
            .iter()
            .filter(|(_, n)| **n > 0)
            .map(|(r, n)| format!("{r} {n}"))
            .collect::<Vec<_>>()
            .join(", ")
    }
    /// The paper's overall rate, for the rows of every object together at the paper's
    /// σ ([`PAPER_SIGMA_MM`]): at another σ it has none to compare with.
    #[must_use]
    pub fn paper(&self) -> Option<f64> {
        (self.object.is_none() && (self.sigma_mm - PAPER_SIGMA_MM).abs() < 1e-9)
            .then(|| paper_rate(self.medium, self.mode))
    }
}

/// The table of `rows`: per σ, scene (one medium each: `media`), object (and all
/// objects) and mode. A trial refused before anything moved (its perturbed pose
/// outside the workspace) is counted under `refused` and in no rate.
///
/// # Errors
/// A damaged stored plan.
pub fn summarise(
    plan: &TrialPlan,
    media: &[Medium],
    rows: &[GraspTrialRow],
) -> Result<Vec<Cell>, TrialsError> {
    let modes = plan.parsed_modes()?;
    let mut cells = Vec::new();
    for si in 0..plan.sigmas_mm.len() as u32 {
        for (ci, medium) in media.iter().enumerate() {
            let ci = ci as u32;
            let objects: Vec<Option<&String>> =
                plan.objects.iter().map(Some).chain([None]).collect();
            for object in objects {
                for mode in &modes {
                    let mine: Vec<&GraspTrialRow> = rows
                        .iter()
                        .filter(|r| {
                            r.key.sigma_index == si
                                && r.key.scene_index == ci
                                && r.key.mode == mode.as_str()
                                && object.is_none_or(|o| *o == r.key.object)
                        })
                        .collect();
                    let refused = FailReason::Refused.as_str();
                    let trials = mine
                        .iter()
                        .filter(|r| r.reason.as_deref() != Some(refused))
                        .count() as u64;
                    let held = mine.iter().filter(|r| r.success).count() as u64;
                    let mut reasons = BTreeMap::new();
                    for r in &FailReason::ALL {
                        let n = mine
                            .iter()
                            .filter(|row| row.reason.as_deref() == Some(r.as_str()))
                            .count() as u64;
                        reasons.insert(r.as_str(), n);
                    }
                    let counted = mine.iter().filter(|r| r.reason.as_deref() != Some(refused));
                    let largest = |f: fn(&GraspTrialRow) -> Option<f64>| {
                        counted
                            .clone()
                            .filter_map(|r| f(r))
                            .filter(|v| v.is_finite())
                            .reduce(f64::max)
                    };
                    let peak_true_max_n = largest(|r| r.peak_true_n);
                    let past_touch_max_mm = largest(|r| r.past_touch_mm);
                    cells.push(Cell {
                        sigma_index: si,
                        sigma_mm: plan.sigmas_mm[si as usize],
                        scene_index: ci,
                        medium: *medium,
                        object: object.cloned(),
                        mode: *mode,
                        trials,
                        held,
                        interval: wilson_interval(held, trials, Z_95)?,
                        reasons,
                        peak_true_max_n,
                        past_touch_max_mm,
                    });
                }
            }
        }
    }
    Ok(cells)
}

/// Open against closed loop on the same perturbations, per σ and medium: trials pair
/// by (object, trial), which draw the same grasp-point offset in both modes. McNemar's
/// exact test asks whether the discordant pairs lean one way more than chance would.
#[derive(Debug, Clone, PartialEq)]
pub struct Paired {
    /// Which σ of the plan.
    pub sigma_index: u32,
    /// Which scene of the session.
    pub scene_index: u32,
    /// The scene's medium.
    pub medium: Medium,
    /// Pairs with both modes stored (a refused trial pairs with nothing).
    pub pairs: u64,
    /// Held in both.
    pub both: u64,
    /// Held open loop only.
    pub open_only: u64,
    /// Held closed loop only.
    pub closed_only: u64,
    /// Held in neither.
    pub neither: u64,
    /// McNemar's exact two-sided p-value.
    pub p: f64,
}

/// The paired comparison of `rows`, per σ and scene (empty unless both modes ran).
#[must_use]
pub fn paired(plan: &TrialPlan, media: &[Medium], rows: &[GraspTrialRow]) -> Vec<Paired> {
    let refused = FailReason::Refused.as_str();
    let usable = |r: &&GraspTrialRow| r.reason.as_deref() != Some(refused);
    let mut out = Vec::new();
    for si in 0..plan.sigmas_mm.len() as u32 {
        for (ci, medium) in media.iter().enumerate() {
            let ci = ci as u32;
            let here = |mode: Mode| -> BTreeMap<(&str, u32), bool> {
                rows.iter()
                    .filter(usable)
                    .filter(|r| {
                        r.key.sigma_index == si
                            && r.key.scene_index == ci
                            && r.key.mode == mode.as_str()
                    })
                    .map(|r| ((r.key.object.as_str(), r.key.trial), r.success))
                    .collect()
            };
            let (open, closed) = (here(Mode::Open), here(Mode::Closed));
            if open.is_empty() || closed.is_empty() {
                continue;
            }
            let mut p = Paired {
                sigma_index: si,
                scene_index: ci,
                medium: *medium,
                pairs: 0,
                both: 0,
                open_only: 0,
                closed_only: 0,
                neither: 0,
                p: 1.0,
            };
            for (key, o) in &open {
                let Some(c) = closed.get(key) else { continue };
                p.pairs += 1;
                match (o, c) {
                    (true, true) => p.both += 1,
                    (true, false) => p.open_only += 1,
                    (false, true) => p.closed_only += 1,
                    (false, false) => p.neither += 1,
                }
            }
            p.p = softtouch_grasp::mcnemar_exact_p(p.open_only, p.closed_only);
            out.push(p);
        }
    }
    out
}

/// Writes the session's files into `dir` (created if need be): the summary and rows
/// CSVs, Figure 4f and, for a σ sweep, success against σ. Returns their paths.
///
/// # Errors
/// The folder or a file cannot be written.
pub fn write_outputs(
    dir: &Path,
    cells: &[Cell],
    rows: &[GraspTrialRow],
    plan: &TrialPlan,
) -> Result<Vec<PathBuf>, TrialsError> {
    std::fs::create_dir_all(dir)
        .map_err(|e| TrialsError::Failed(format!("cannot create {}: {e}", dir.display())))?;
    let csv = dir.join("grasp-trials.csv");
    write_summary_csv(&csv, cells, plan.sweep.as_ref())?;
    let rows_csv = dir.join("grasp-trials-rows.csv");
    write_rows_csv(&rows_csv, rows, plan.sweep.as_ref())?;
    let png = dir.join("grasp-trials.png");
    write_bars(&png, cells, plan)?;
    let mut written = vec![csv, rows_csv, png];
    if plan.sigmas_mm.len() > 1 {
        let sweep = dir.join("grasp-trials-sigma.png");
        write_sweep(&sweep, cells, plan)?;
        written.push(sweep);
    }
    if let Some(sweep) = &plan.sweep {
        let csv = dir.join("grasp-trials-sweep.csv");
        write_value_sweep_csv(&csv, cells, plan, sweep)?;
        let png = dir.join("grasp-trials-sweep.png");
        write_value_sweep(&png, cells, plan, sweep)?;
        written.extend([csv, png]);
    }
    Ok(written)
}

/// `grasp-trials-sweep.csv`: one line per swept value, σ, medium, object (and all) and
/// mode, with the Wilson 95 % interval and the failures.
///
/// # Errors
/// The file cannot be written.
pub fn write_value_sweep_csv(
    path: &Path,
    cells: &[Cell],
    plan: &TrialPlan,
    sweep: &SceneSweep,
) -> Result<(), TrialsError> {
    let mut text = String::from(
        "path,value,sigma_mm,medium,object,mode,trials,held,rate,wilson_lo,wilson_hi,slip,crush,miss,timeout,device_fault,estimate_stalled,false_confirm,refused\n",
    );
    let opt = |v: Option<f64>| v.map_or_else(String::new, |f| format!("{f}"));
    for c in cells {
        let Some(value) = sweep.value_of(c.scene_index) else {
            continue;
        };
        let r = |k: &str| c.reasons.get(k).copied().unwrap_or(0);
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            csv_field(&sweep.path),
            csv_field(value),
            plan.sigmas_mm
                .get(c.sigma_index as usize)
                .map_or_else(String::new, |s| format!("{s}")),
            medium_name(c.medium),
            csv_field(c.object.as_deref().unwrap_or("all")),
            c.mode.as_str(),
            c.trials,
            c.held,
            opt(c.rate()),
            c.interval[0],
            c.interval[1],
            r("slip"),
            r("crush"),
            r("miss"),
            r("timeout"),
            r("device_fault"),
            r("estimate_stalled"),
            r("false_confirm"),
            r("refused"),
        ));
    }
    write_file(path, &text)
}

/// Success against the swept value (all objects, the first σ): one bar per medium and
/// mode at each value, with its Wilson interval and n.
///
/// # Errors
/// The chart cannot be drawn or written.
pub fn write_value_sweep(
    path: &Path,
    cells: &[Cell],
    plan: &TrialPlan,
    sweep: &SceneSweep,
) -> Result<(), TrialsError> {
    let pooled: Vec<&Cell> = cells
        .iter()
        .filter(|c| c.object.is_none() && c.sigma_index == 0)
        .collect();
    // A series per base scene (medium) and mode.
    let mut keys: Vec<(u32, Medium, Mode)> = Vec::new();
    for c in &pooled {
        let base = c.scene_index % sweep.per_value.max(1);
        if !keys.iter().any(|k| k.0 == base && k.2 == c.mode) {
            keys.push((base, c.medium, c.mode));
        }
    }
    let groups: Vec<String> = (0..sweep.values.len())
        .map(|i| sweep.value_label(i))
        .collect();
    let series: Vec<BarSeries> = keys
        .iter()
        .map(|(base, medium, mode)| {
            let cell = |v: usize| {
                pooled.iter().find(|c| {
                    c.scene_index % sweep.per_value.max(1) == *base
                        && c.mode == *mode
                        && sweep.value_index(c.scene_index) == Some(v)
                })
            };
            BarSeries {
                label: format!("{} {} loop", medium_name(*medium), mode.as_str()),
                bars: (0..groups.len())
                    .map(|i| cell(i).and_then(|c| Some((c.rate()?, c.interval[0], c.interval[1]))))
                    .collect(),
                reference: vec![None; groups.len()],
                notes: (0..groups.len())
                    .map(|i| cell(i).map(|c| format!("n={}", c.trials)))
                    .collect(),
            }
        })
        .collect();
    let sigma = plan.sigmas_mm.first().copied().unwrap_or(f64::NAN);
    let title = format!(
        "Grasp success against {} (all objects, σ {sigma} mm; Wilson 95 %)",
        sweep.path
    );
    bar_chart(
        path,
        &BarChart {
            title: &title,
            x_label: Some(&sweep.path),
            y_label: "success rate (held/n)",
            groups: &groups,
            series: &series,
            y_range: (0.0, 1.08),
            y_labels_up_to: Some(1.0),
        },
        (
            // Wide enough for its bars and for its title (at most 12 px a character).
            (60 * (groups.len() * keys.len().max(1)) as u32 + 240)
                .max(12 * title.chars().count() as u32 + 80)
                .clamp(720, 2400),
            520,
        ),
    )
    .map_err(|e| TrialsError::Failed(e.to_string()))
}

fn write_file(path: &Path, text: &str) -> Result<(), TrialsError> {
    std::fs::write(path, text)
        .map_err(|e| TrialsError::Failed(format!("cannot write {}: {e}", path.display())))
}

/// A CSV field, quoted where it must be.
#[must_use]
pub fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_owned()
    }
}

/// `grasp-trials.csv`: one line per cell.
///
/// # Errors
/// The file cannot be written.
pub fn write_summary_csv(
    path: &Path,
    cells: &[Cell],
    sweep: Option<&SceneSweep>,
) -> Result<(), TrialsError> {
    let mut text = String::from(
        "sigma_index,medium,object,mode,trials,held,rate,wilson_lo,wilson_hi,paper_rate,slip,crush,miss,timeout,device_fault,estimate_stalled,false_confirm,refused,peak_true_max_n,past_touch_max_mm,scene_index,scene_value\n",
    );
    let opt = |v: Option<f64>| v.map_or_else(String::new, |f| format!("{f}"));
    for c in cells {
        let r = |k: &str| c.reasons.get(k).copied().unwrap_or(0);
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            c.sigma_index,
            medium_name(c.medium),
            csv_field(c.object.as_deref().unwrap_or("all")),
            c.mode.as_str(),
            c.trials,
            c.held,
            opt(c.rate()),
            c.interval[0],
            c.interval[1],
            opt(c.paper()),
            r("slip"),
            r("crush"),
            r("miss"),
            r("timeout"),
            r("device_fault"),
            r("estimate_stalled"),
            r("false_confirm"),
            r("refused"),
            opt(c.peak_true_max_n),
            opt(c.past_touch_max_mm),
            c.scene_index,
            scene_value(sweep, c.scene_index),
        ));
    }
    write_file(path, &text)
}

/// The swept value of scene `scene_index` as a CSV field (empty without a sweep): rows
/// of different values are told apart in every table.
fn scene_value(sweep: Option<&SceneSweep>, scene_index: u32) -> String {
    sweep
        .and_then(|s| s.value_of(scene_index))
        .map_or_else(String::new, csv_field)
}

/// `grasp-trials-rows.csv`: one line per trial.
///
/// # Errors
/// The file cannot be written.
pub fn write_rows_csv(
    path: &Path,
    rows: &[GraspTrialRow],
    sweep: Option<&SceneSweep>,
) -> Result<(), TrialsError> {
    let mut text = String::from(
        "sigma_m,medium,object,mode,trial,dx_m,dy_m,dz_m,commanded_width_m,final_width_m,peak_estimate_n,peak_true_n,past_touch_mm,success,reason,confirmed_after_s,wall_s,scene_index,scene_value\n",
    );
    let opt = |v: Option<f64>| v.map_or_else(String::new, |f| format!("{f}"));
    for r in rows {
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            r.sigma_m,
            r.medium,
            csv_field(&r.key.object),
            r.key.mode,
            r.key.trial,
            r.offset_m[0],
            r.offset_m[1],
            r.offset_m[2],
            r.commanded_width_m,
            r.final_width_m,
            opt(r.peak_estimate_n),
            opt(r.peak_true_n),
            opt(r.past_touch_mm),
            u8::from(r.success),
            r.reason.as_deref().unwrap_or(""),
            opt(r.confirmed_after_s),
            r.wall_s,
            r.key.scene_index,
            scene_value(sweep, r.key.scene_index),
        ));
    }
    write_file(path, &text)
}

/// Figure 4f: the first σ's success rates with their intervals, per medium and object.
///
/// # Errors
/// The chart cannot be drawn or written.
pub fn write_bars(path: &Path, cells: &[Cell], plan: &TrialPlan) -> Result<(), TrialsError> {
    let first: Vec<&Cell> = cells.iter().filter(|c| c.sigma_index == 0).collect();
    let mut groups: Vec<(u32, Option<String>)> = Vec::new();
    for c in &first {
        let g = (c.scene_index, c.object.clone());
        if !groups.contains(&g) {
            groups.push(g);
        }
    }
    let mut modes: Vec<Mode> = Vec::new();
    for c in &first {
        if !modes.contains(&c.mode) {
            modes.push(c.mode);
        }
    }
    let names: Vec<String> = groups
        .iter()
        .map(|(si, o)| {
            let medium = first
                .iter()
                .find(|c| c.scene_index == *si)
                .map_or("?", |c| medium_name(c.medium));
            bar_group_name(plan, medium, *si, o.as_deref())
        })
        .collect();
    let series: Vec<BarSeries> = modes
        .iter()
        .map(|m| {
            let cell = |g: &(u32, Option<String>)| {
                first
                    .iter()
                    .find(|c| c.mode == *m && c.scene_index == g.0 && c.object == g.1)
            };
            BarSeries {
                label: format!("{} loop (paper: black tick)", m.as_str()),
                bars: groups
                    .iter()
                    .map(|g| cell(g).and_then(|c| Some((c.rate()?, c.interval[0], c.interval[1]))))
                    .collect(),
                reference: groups
                    .iter()
                    .map(|g| {
                        cell(g)
                            .filter(|_| paper_tick_applies(plan, g.0))
                            .and_then(|c| c.paper())
                    })
                    .collect(),
                notes: groups
                    .iter()
                    .map(|g| cell(g).map(|c| format!("n={}", c.trials)))
                    .collect(),
            }
        })
        .collect();
    let title = format!(
        "Grasp success, σ = {} mm (Wilson 95 % intervals)",
        plan.sigmas_mm.first().copied().unwrap_or(0.0)
    );
    bar_chart(
        path,
        &BarChart {
            title: &title,
            x_label: None,
            y_label: "success rate (held/n)",
            groups: &names,
            series: &series,
            // Room above 100 % for the bars' notes (n), with no tick there.
            y_range: (0.0, 1.08),
            y_labels_up_to: Some(1.0),
        },
        ((180 * names.len() as u32).clamp(640, 2400), 520),
    )
    .map_err(|e| TrialsError::Failed(e.to_string()))
}

/// A Figure 4f group's name: `water/all`, and in a swept session its scene's value
/// (`water/all, wet_friction=0.2`), so no two groups read alike.
#[must_use]
pub fn bar_group_name(
    plan: &TrialPlan,
    medium: &str,
    scene_index: u32,
    object: Option<&str>,
) -> String {
    let object = object.unwrap_or("all");
    match plan.sweep.as_ref().and_then(|s| {
        let i = s.value_index(scene_index)?;
        let last = s.path.rsplit('.').next().unwrap_or(&s.path);
        Some(format!("{last}={}", s.value_label(i)))
    }) {
        Some(value) => format!("{medium}/{object}, {value}"),
        None => format!("{medium}/{object}"),
    }
}

/// Whether the paper's rate is drawn beside scene `scene_index`'s bars: the paper's
/// scenes are the shipped ones, so in a swept session only at the value they ship
/// with (none where the scenes do not agree on one).
#[must_use]
pub fn paper_tick_applies(plan: &TrialPlan, scene_index: u32) -> bool {
    match &plan.sweep {
        None => true,
        Some(s) => s
            .value_of(scene_index)
            .is_some_and(|v| s.shipped.as_deref() == Some(v)),
    }
}

/// Success of all objects against σ, per medium and mode.
///
/// # Errors
/// The chart cannot be drawn or written.
pub fn write_sweep(path: &Path, cells: &[Cell], plan: &TrialPlan) -> Result<(), TrialsError> {
    let mut keys: Vec<(u32, Medium, Mode)> = Vec::new();
    for c in cells.iter().filter(|c| c.object.is_none()) {
        if !keys.contains(&(c.scene_index, c.medium, c.mode)) {
            keys.push((c.scene_index, c.medium, c.mode));
        }
    }
    let groups: Vec<String> = plan.sigmas_mm.iter().map(|s| sigma_label(*s)).collect();
    // One bar per medium and mode at each σ, with its Wilson interval and n.
    let series: Vec<BarSeries> = keys
        .iter()
        .map(|(si, medium, mode)| {
            let cell = |sigma: usize| {
                cells.iter().find(|c| {
                    c.object.is_none()
                        && c.scene_index == *si
                        && c.mode == *mode
                        && c.sigma_index as usize == sigma
                })
            };
            BarSeries {
                label: format!("{} {} loop", medium_name(*medium), mode.as_str()),
                bars: (0..groups.len())
                    .map(|i| cell(i).and_then(|c| Some((c.rate()?, c.interval[0], c.interval[1]))))
                    .collect(),
                // The paper's rate beside the paper's σ (a black tick).
                reference: plan
                    .sigmas_mm
                    .iter()
                    .map(|s| {
                        ((s - PAPER_SIGMA_MM).abs() < 1e-9).then(|| paper_rate(*medium, *mode))
                    })
                    .collect(),
                notes: (0..groups.len())
                    .map(|i| cell(i).map(|c| format!("n={}", c.trials)))
                    .collect(),
            }
        })
        .collect();
    bar_chart(
        path,
        &BarChart {
            title: "Grasp success against σ (all objects; Wilson 95 %)",
            x_label: Some("σ per axis"),
            y_label: "success rate (held/n)",
            groups: &groups,
            series: &series,
            // Room above 100 % for the bars' notes (n), with no tick there.
            y_range: (0.0, 1.08),
            y_labels_up_to: Some(1.0),
        },
        (
            (60 * (groups.len() * keys.len().max(1)) as u32 + 240).clamp(720, 2400),
            520,
        ),
    )
    .map_err(|e| TrialsError::Failed(e.to_string()))
}

/// Successes per medium and mode, `air open 23/50, …`, refused trials left out; per σ
/// where the session has several (`σ 2 mm`), and per scene where a medium has several
/// (a swept value, or a scene that does not have the swept path replayed at each value:
/// `scene 2`). Trials of different σ or scenes are never pooled into one n.
#[must_use]
pub fn session_summary(trials: &[crate::store::GraspTrialRow]) -> String {
    let kept: Vec<&crate::store::GraspTrialRow> = trials
        .iter()
        .filter(|t| t.reason.as_deref() != Some("refused"))
        .collect();
    let mut sigmas: Vec<u32> = kept.iter().map(|t| t.key.sigma_index).collect();
    sigmas.sort_unstable();
    sigmas.dedup();
    let scenes_of = |medium: &str| {
        let mut v: Vec<u32> = kept
            .iter()
            .filter(|t| t.medium == medium)
            .map(|t| t.key.scene_index)
            .collect();
        v.sort_unstable();
        v.dedup();
        v.len()
    };
    // (medium, mode, σ index, scene index), its label, held, n
    type Key = (String, String, u32, u32);
    let mut cells: Vec<(Key, String, usize, usize)> = Vec::new();
    for t in &kept {
        let key = (
            t.medium.clone(),
            t.key.mode.clone(),
            t.key.sigma_index,
            t.key.scene_index,
        );
        let i = cells.iter().position(|c| c.0 == key).unwrap_or_else(|| {
            let mut label = format!("{} {}", t.medium, t.key.mode);
            if sigmas.len() > 1 {
                // To the micrometre: 0.007 m prints as 7, not 7.000000000000001.
                label.push_str(&format!(" σ {} mm", (t.sigma_m * 1e6).round() / 1e3));
            }
            if scenes_of(&t.medium) > 1 {
                label.push_str(&format!(" scene {}", t.key.scene_index));
            }
            cells.push((key, label, 0, 0));
            cells.len() - 1
        });
        cells[i].2 += usize::from(t.success);
        cells[i].3 += 1;
    }
    cells
        .iter()
        .map(|(_, label, s, n)| format!("{label} {s}/{n}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A range of row ids as a list shows it: `7`, or `7–56`.
#[must_use]
pub fn id_span(first: i64, last: i64) -> String {
    if first == last {
        first.to_string()
    } else {
        format!("{first}–{last}")
    }
}

#[cfg(test)]
mod tests;
