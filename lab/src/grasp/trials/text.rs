//! The terminal's text of a trial session: its header, the wall time of the trials
//! run, the success tables (per scene, against a swept value, open against closed)
//! and the spread across models. Written to any `Write`; `grasp trials` prints it.

use std::io::{self, Write};

use softtouch_grasp::Mode;
use softtouch_schemas::Medium;

use super::experiment::SimRun;
use super::table::{Cell, Paired};
use super::{TrialPlan, TrialTiming, medium_name};

/// The wall time of the trials this invocation ran, per medium and mode: cycles (one
/// a frame), ms per cycle, mean and slowest trial and how many took at most 1 s.
pub fn print_timings(timings: &[TrialTiming], fps: f64, out: &mut dyn Write) -> io::Result<()> {
    writeln!(
        out,
        "\nwall time of the trials run now ({fps} Hz on virtual time):\n{:<7}{:<8}{:>7}{:>9}{:>10}{:>8}{:>8}{:>9}",
        "medium", "mode", "trials", "cycles", "ms/cycle", "mean s", "max s", "≤ 1 s"
    )?;
    let mut groups: Vec<(Medium, Mode)> = Vec::new();
    for t in timings {
        if !groups.contains(&(t.medium, t.mode)) {
            groups.push((t.medium, t.mode));
        }
    }
    for (medium, mode) in groups {
        let of: Vec<&TrialTiming> = timings
            .iter()
            .filter(|t| t.medium == medium && t.mode == mode)
            .collect();
        let wall_s: f64 = of.iter().map(|t| t.wall_s).sum();
        let cycles: usize = of.iter().map(|t| t.cycles).sum();
        let max_s = of.iter().map(|t| t.wall_s).fold(0.0, f64::max);
        let within = of.iter().filter(|t| t.wall_s <= 1.0).count();
        let per_cycle = if cycles == 0 {
            "–".to_owned()
        } else {
            format!("{:.3}", 1e3 * wall_s / cycles as f64)
        };
        writeln!(
            out,
            "{:<7}{:<8}{:>7}{:>9}{:>10}{:>8.3}{:>8.3}{:>9}",
            medium_name(medium),
            mode.as_str(),
            of.len(),
            cycles,
            per_cycle,
            wall_s / of.len() as f64,
            max_s,
            format!("{within}/{}", of.len())
        )?;
    }
    Ok(())
}

pub fn fmt_duration(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    if s >= 60 {
        format!("{}m{:02}s", s / 60, s % 60)
    } else {
        format!("{s}s")
    }
}

/// The session's first line (id, model, seed, trials planned, stored and to run) and
/// its setup lines, before any trial runs.
pub fn print_header(
    out: &mut dyn Write,
    what: &str,
    (id, model, sha256, seed): (i64, &str, &str, u64),
    (planned, todo): (usize, usize),
    setup: &[String],
) -> io::Result<()> {
    writeln!(
        out,
        "{what} {id}: model `{model}` (sha256 {}), seed {seed}, {planned} {} planned, {} stored, {todo} to run",
        &sha256[..12.min(sha256.len())],
        if planned == 1 { "trial" } else { "trials" },
        planned - todo,
    )?;
    for line in setup {
        writeln!(out, "{line}")?;
    }
    Ok(())
}

/// A row of the spread: its σ, medium and mode, and each model's `(name, held, n)`.
pub type SpreadRow = (String, Vec<(String, u64, u64)>);

/// Per σ, medium and mode (all objects): each model's held/n, from the tables its
/// session printed.
pub fn model_spread(runs: &[(String, SimRun)]) -> Vec<SpreadRow> {
    let mut rows: Vec<SpreadRow> = Vec::new();
    for (model, run) in runs {
        for c in run.table.iter().filter(|c| c.object.is_none()) {
            // A swept value is part of the row: different values are not different
            // models of one row.
            let value = run.sweep.as_ref().map_or(String::new(), |s| {
                s.value_index(c.scene_index).map_or(String::new(), |i| {
                    format!(" {}={}", s.path, s.value_label(i))
                })
            });
            let key = format!(
                "σ {} mm {} {}{value}",
                run.sigmas_mm[c.sigma_index as usize],
                medium_name(c.medium),
                c.mode.as_str()
            );
            let i = rows.iter().position(|r| r.0 == key).unwrap_or_else(|| {
                rows.push((key, Vec::new()));
                rows.len() - 1
            });
            rows[i].1.push((model.clone(), c.held, c.trials));
        }
    }
    rows
}

pub fn print_spread(rows: &[SpreadRow], out: &mut dyn Write) -> io::Result<()> {
    writeln!(
        out,
        "\nacross models (all objects; sd: sample standard deviation of the models' rates):"
    )?;
    for (key, per) in rows {
        let rates: Vec<f64> = per
            .iter()
            .filter(|(_, _, n)| *n > 0)
            .map(|(_, h, n)| *h as f64 / *n as f64)
            .collect();
        let mean = rates.iter().sum::<f64>() / rates.len().max(1) as f64;
        let sd = if rates.len() > 1 {
            (rates.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (rates.len() - 1) as f64)
                .sqrt()
        } else {
            f64::NAN
        };
        let (lo, hi) = rates
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), r| {
                (a.min(*r), b.max(*r))
            });
        let each: Vec<String> = per.iter().map(|(m, h, n)| format!("{m} {h}/{n}")).collect();
        let p = |v: f64| {
            if v.is_finite() {
                format!("{:.0} %", 100.0 * v)
            } else {
                "–".into()
            }
        };
        writeln!(
            out,
            "{key:<26} mean {:>5}  sd {:>5}  range {}–{}  {}",
            p(mean),
            p(sd),
            p(lo),
            p(hi),
            each.join(", ")
        )?;
    }
    Ok(())
}

fn pct(v: Option<f64>) -> String {
    v.map_or_else(|| "–".to_owned(), |v| format!("{:.0}%", 100.0 * v))
}

pub fn print_table(cells: &[Cell], plan: &TrialPlan, out: &mut dyn Write) -> io::Result<()> {
    let mut last = None;
    for c in cells {
        if last != Some((c.sigma_index, c.scene_index)) {
            last = Some((c.sigma_index, c.scene_index));
            let swept = plan
                .sweep
                .as_ref()
                .and_then(|s| Some(format!("; {} = {}", s.path, s.value_of(c.scene_index)?)))
                .unwrap_or_default();
            writeln!(
                out,
                "\nσ = {} mm, {} (scene {}{swept}):\n{:<14} {:<7} {:>7} {:>6} {:>15} {:>7} {:>10}  failures",
                plan.sigmas_mm[c.sigma_index as usize],
                medium_name(c.medium),
                c.scene_index,
                "object",
                "mode",
                "held/n",
                "rate",
                "Wilson 95%",
                "paper",
                "grip max"
            )?;
        }
        writeln!(
            out,
            "{:<14} {:<7} {:>7} {:>6} {:>15} {:>7} {:>10}  {}",
            c.object.as_deref().unwrap_or("all"),
            c.mode.as_str(),
            format!("{}/{}", c.held, c.trials),
            pct(c.rate()),
            format!(
                "[{:.0}%, {:.0}%]",
                100.0 * c.interval[0],
                100.0 * c.interval[1]
            ),
            pct(c.paper()),
            c.grip_text(),
            c.failures_text()
        )?;
    }
    writeln!(
        out,
        "\ngrip max: the largest true grip force of the trials (simulator), or on a rig the deepest closing past the calibrated touch"
    )?;
    Ok(())
}

/// A scene sweep's summary: success against the value per medium and mode (all
/// objects), then per object, medium and mode the first value held in at least 90 %
/// of its trials.
pub fn print_sweep(cells: &[Cell], plan: &TrialPlan, out: &mut dyn Write) -> io::Result<()> {
    let Some(sweep) = &plan.sweep else {
        return Ok(());
    };
    for (si, sigma) in plan.sigmas_mm.iter().enumerate() {
        writeln!(
            out,
            "\nsuccess against {} (σ = {sigma} mm, all objects):\n{:>16} {:<7} {:<7} {:>7} {:>6} {:>15}  failures",
            sweep.path, "value", "medium", "mode", "held/n", "rate", "Wilson 95%"
        )?;
        let here = |c: &&Cell| c.sigma_index as usize == si;
        for c in cells.iter().filter(here).filter(|c| c.object.is_none()) {
            writeln!(
                out,
                "{:>16} {:<7} {:<7} {:>7} {:>6} {:>15}  {}",
                sweep
                    .value_index(c.scene_index)
                    .map_or_else(|| "?".to_owned(), |i| sweep.value_label(i)),
                medium_name(c.medium),
                c.mode.as_str(),
                format!("{}/{}", c.held, c.trials),
                pct(c.rate()),
                format!(
                    "[{:.0}%, {:.0}%]",
                    100.0 * c.interval[0],
                    100.0 * c.interval[1]
                ),
                c.failures_text()
            )?;
        }
        writeln!(
            out,
            "first value held in at least 90 % of trials (σ = {sigma} mm; values in the order swept):"
        )?;
        let mut keys: Vec<(String, u32, Mode)> = Vec::new();
        for c in cells.iter().filter(here) {
            let key = (
                c.object.clone().unwrap_or_else(|| "all".into()),
                c.scene_index % sweep.per_value.max(1),
                c.mode,
            );
            if !keys.contains(&key) {
                keys.push(key);
            }
        }
        for (object, base, mode) in &keys {
            let mine: Vec<&Cell> = cells
                .iter()
                .filter(here)
                .filter(|c| {
                    c.object.clone().unwrap_or_else(|| "all".into()) == *object
                        && c.scene_index % sweep.per_value.max(1) == *base
                        && c.mode == *mode
                })
                .collect();
            let Some(medium) = mine.first().map(|c| medium_name(c.medium)) else {
                continue;
            };
            let first = mine
                .iter()
                .find(|c| c.trials > 0 && c.held * 10 >= c.trials * 9)
                .map_or_else(
                    || "none".to_owned(),
                    |c| {
                        format!(
                            "{} ({}/{})",
                            sweep.value_of(c.scene_index).unwrap_or("?"),
                            c.held,
                            c.trials
                        )
                    },
                );
            writeln!(
                out,
                "  {object:<14} {medium:<7} {:<7} {first}",
                mode.as_str()
            )?;
        }
    }
    Ok(())
}

/// Open against closed on the same perturbations, with McNemar's exact test.
pub fn print_paired(pairs: &[Paired], plan: &TrialPlan, out: &mut dyn Write) -> io::Result<()> {
    if pairs.is_empty() {
        return Ok(());
    }
    writeln!(
        out,
        "\nopen against closed on the same perturbations (pairs by object and trial; McNemar's exact test):\n{:>6} {:<7} {:>6} {:>6} {:>10} {:>12} {:>8} {:>9}",
        "σ mm", "medium", "pairs", "both", "open only", "closed only", "neither", "p"
    )?;
    for p in pairs {
        writeln!(
            out,
            "{:>6} {:<7} {:>6} {:>6} {:>10} {:>12} {:>8} {:>9.4}",
            plan.sigmas_mm[p.sigma_index as usize],
            match plan.sweep.as_ref().and_then(|s| s.value_of(p.scene_index)) {
                Some(v) => format!("{} at {v}", medium_name(p.medium)),
                None => medium_name(p.medium).to_owned(),
            },
            p.pairs,
            p.both,
            p.open_only,
            p.closed_only,
            p.neither,
            p.p
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_read_as_minutes_and_seconds() {
        assert_eq!(fmt_duration(125.4), "2m05s");
        assert_eq!(fmt_duration(59.4), "59s");
        assert_eq!(fmt_duration(-3.0), "0s");
    }
}
