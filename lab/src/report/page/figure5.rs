//! Figure 5 from the stored results: force following (the latest `grasp follow`),
//! disturbance (`grasp disturb`), twist (`grasp twist`) and `bench grasp`'s
//! trade-offs. Each part shows its provenance; a table that does not read back costs
//! its part, with a note.

use super::*;
use crate::report::results::{Columns, provenance};
use crate::store::StoredResult;

/// Points drawn per line at most: enough for a 60 s run at 120 Hz to keep its shape.
const MAX_POINTS: usize = 1500;

fn line(label: &str, t: &[f64], v: &[f64]) -> Series {
    let keep = svg::downsample_indices(t.len().min(v.len()), MAX_POINTS);
    Series {
        label: label.into(),
        points: keep.iter().map(|&i| (t[i], v[i])).collect(),
        style: SeriesStyle::Line,
    }
}

fn time_figure(title: &str, y_label: &str, series: &[Series]) -> Result<Markup, ReportError> {
    time_figure_in(title, y_label, series, None, (560, 320))
}

fn time_figure_in(
    title: &str,
    y_label: &str,
    series: &[Series],
    y_range: Option<(f64, f64)>,
    size: svg::Size,
) -> Result<Markup, ReportError> {
    Ok(figure(svg::xy(
        &Xy {
            title,
            x_label: "time, s",
            y_label,
            series,
            diagonal: false,
            y_range,
            marker_px: 2,
        },
        size,
    )?))
}

/// A part that could not be read: the reason, in place of the part.
fn unreadable(what: &str, why: &str) -> Markup {
    html! { p.todo { "Could not read " (what) ": " (why) } }
}

fn prov(r: &StoredResult) -> Markup {
    html! { p.prov { (provenance(&r.row)) } }
}

pub(super) fn figure5_section(c: &Content) -> Result<Markup, ReportError> {
    let follow = c.results.latest("grasp follow");
    let disturb = c.results.latest("grasp disturb");
    let twist = c.results.latest("grasp twist");
    let bench = c.results.latest("bench grasp");
    Ok(html! {
        section #figure-5 {
            h2 { "Figure 5: following, disturbance, twist" }
            p.note { "The latest stored result of each verb (" code { "softtouch results" } " lists them all). On the simulator \"true\" is its contact force; on a rig only the estimate exists." }
            h3 { "Force following" }
            @match follow {
                Some(r) => (follow_part(r)?),
                None => (todo_in(c, "No force following stored. The paper holds 0.4, 1.6 and 3 N in turn:", &["softtouch grasp follow --model {model} --targets 0.4,1.6,3"])),
            }
            h3 { "Disturbance" }
            @match disturb {
                Some(r) => (disturb_part(r)?),
                None => (todo_in(c, "No disturbance run stored. The paper turns the tube 45°, 60°, then −90°:", &["softtouch grasp disturb --model {model}"])),
            }
            h3 { "Twist" }
            @match twist {
                Some(r) => (twist_part(r)?),
                None => (todo_in(c, "No twist stored:", &["softtouch grasp twist --model {model}"])),
            }
            h3 { "Gain, tolerance and rate (bench grasp)" }
            @match bench {
                Some(r) => (bench_part(r)),
                None => (todo_in(c, "No grasp benchmark stored:", &["softtouch bench grasp --model {model}"])),
            }
        }
    })
}

fn follow_part(r: &StoredResult) -> Result<Markup, ReportError> {
    let id = r.row.result_id;
    let read = || -> Result<_, String> {
        let cycles = Columns::of(r, "grasp-follow.csv")?;
        let t = cycles.num("t_s")?;
        let series = vec![
            line("commanded F_ref", &t, &cycles.num("target_n")?),
            line("estimate F_est", &t, &cycles.num("estimate_n")?),
            line("true", &t, &cycles.num("true_n")?),
        ];
        let m = Columns::of(r, "grasp-follow-metrics.csv")?;
        let cols = [
            "target_n",
            "est_rise_s",
            "est_settle_s",
            "est_overshoot_n",
            "est_ss_error_n",
            "est_rms_n",
            "true_ss_error_n",
            "true_rms_n",
        ];
        let mut values = cols
            .iter()
            .map(|c| m.num(c))
            .collect::<Result<Vec<_>, _>>()?;
        // The grip columns came later: a follow stored before them shows "–".
        for c in ["peak_true_n", "past_touch_mm"] {
            values.push(m.num(c).unwrap_or_else(|_| vec![f64::NAN; m.len()]));
        }
        Ok((series, values, m.len()))
    };
    let (series, v, n) = match read() {
        Ok(x) => x,
        Err(e) => return Ok(html! { (prov(r)) (unreadable("the following", &e)) }),
    };
    let fig = time_figure("Force following", "grip force, N", &series)?;
    Ok(html! {
        (prov(r))
        table {
            tr { th { "target N" } th { "rise s" } th { "settle s" } th { "overshoot N" } th { "ss error N" } th { "RMS N" } th { "true ss error N" } th { "true RMS N" } th { "peak true N" } th { "past touch mm" } }
            @for i in 0..n {
                tr {
                    td { (f(v[0][i], 2)) } td { (f(v[1][i], 3)) } td { (f(v[2][i], 3)) } td { (f(v[3][i], 3)) }
                    td data-k=(format!("follow-{id}-{i}-ss")) { (f(v[4][i], 3)) }
                    td { (f(v[5][i], 3)) } td { (f(v[6][i], 3)) } td { (f(v[7][i], 3)) }
                    td data-k=(format!("follow-{id}-{i}-peak-true")) { (f(v[8][i], 2)) }
                    td data-k=(format!("follow-{id}-{i}-past-touch")) { (f(v[9][i], 2)) }
                }
            }
        }
        p.note { "Settle: the first time after which the force stays within ±δ of the target; – never. Errors are the estimate's (the loop sees nothing else) and, where the simulator gives it, the true force's. Peak true: the largest true grip force of the hold (simulator); past touch: the deepest closing past the calibrated first touch, what a rig shows of the grip without a true force." }
        div.figs { (fig) }
    })
}

fn disturb_part(r: &StoredResult) -> Result<Markup, ReportError> {
    let read = || -> Result<_, String> {
        let cycles = Columns::of(r, "grasp-disturb.csv")?;
        let t = cycles.num("t_s")?;
        let force = vec![
            line("target", &t, &cycles.num("target_n")?),
            line("estimate", &t, &cycles.num("estimate_n")?),
            line("true", &t, &cycles.num("true_n")?),
        ];
        let yaw = vec![line("object yaw", &t, &cycles.num("object_yaw_deg")?)];
        Ok((force, yaw))
    };
    let (force, yaw) = match read() {
        Ok(x) => x,
        Err(e) => return Ok(html! { (prov(r)) (unreadable("the disturbance", &e)) }),
    };
    Ok(html! {
        (prov(r))
        p { (r.row.summary) }
        div.figs {
            (time_figure("Disturbance: grip force", "grip force, N", &force)?)
            (time_figure("Disturbance: the turns", "object yaw, °", &yaw)?)
        }
    })
}

fn rms(v: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = v
        .filter(|x| x.is_finite())
        .fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
    if n == 0 {
        f64::NAN
    } else {
        (sum / n as f64).sqrt()
    }
}

fn twist_part(r: &StoredResult) -> Result<Markup, ReportError> {
    let id = r.row.result_id;
    // The simulator's table has the true τz; the rig's only the estimate.
    let name = if r.table("grasp-twist.csv").is_some() {
        "grasp-twist.csv"
    } else {
        "grasp-twist-rig.csv"
    };
    let read = || -> Result<_, String> {
        let cycles = Columns::of(r, name)?;
        let t = cycles.num("t_s")?;
        let loops = cycles.text("wrist_loop")?;
        let est = cycles
            .num("tz_estimate_nmm")
            .or_else(|_| cycles.num("torque_z_nmm"))?;
        let truth = cycles.num("tz_true_nmm").ok();
        let mut rows = Vec::new();
        let mut series = Vec::new();
        // The numbers as the verb computed and printed them (from the first turn on);
        // results stored before that table existed are scored over every cycle.
        let metrics = Columns::of(r, "grasp-twist-metrics.csv").ok();
        let scored = match &metrics {
            Some(m) => {
                let (state, n) = (m.text("wrist_loop")?, m.num("cycles_scored")?);
                let (e, t) = (m.num("tz_rms_nmm")?, m.num("true_tz_rms_nmm")?);
                for i in 0..state.len() {
                    rows.push(((*state[i]).to_owned(), n[i] as usize, e[i], t[i]));
                }
                "from the first turn on (the settle before it left out)"
            }
            None => "over every cycle",
        };
        for state in ["off", "on"] {
            let idx: Vec<usize> = (0..t.len()).filter(|&i| loops[i] == state).collect();
            if idx.is_empty() {
                continue;
            }
            let ts: Vec<f64> = idx.iter().map(|&i| t[i]).collect();
            let pick = |v: &[f64]| idx.iter().map(|&i| v[i]).collect::<Vec<f64>>();
            let shown = truth.as_deref().unwrap_or(&est);
            series.push((
                state,
                line(
                    &format!(
                        "{} τz, wrist loop {state}",
                        if truth.is_some() { "true" } else { "estimated" }
                    ),
                    &ts,
                    &pick(shown),
                ),
            ));
            if metrics.is_none() {
                rows.push((
                    state.to_owned(),
                    idx.len(),
                    rms(pick(&est).into_iter()),
                    truth
                        .as_deref()
                        .map_or(f64::NAN, |tr| rms(pick(tr).into_iter())),
                ));
            }
        }
        Ok((rows, series, scored))
    };
    let (rows, series, scored) = match read() {
        Ok(x) => x,
        Err(e) => return Ok(html! { (prov(r)) (unreadable("the twist", &e)) }),
    };
    let all: Vec<Series> = series.iter().map(|(_, s)| s.clone()).collect();
    let y_range = softtouch_collector::plot::finite_bounds(&all)
        .map(|(_, _, lo, hi)| softtouch_collector::plot::pad(lo, hi));
    Ok(html! {
        (prov(r))
        // The stored summary says each run's grip at its firmest (peak true force, or
        // on a rig the closing past the touch).
        p data-k=(format!("twist-{id}-summary")) { (r.row.summary) }
        p { "τz RMS " (scored) "." }
        table {
            tr { th.l { "wrist loop" } th { "cycles" } th { "estimated τz RMS N·mm" } th { "true τz RMS N·mm" } }
            @for (state, n, e, t) in &rows {
                tr { td.l { (state) } td { (n) } td { (f(*e, 3)) } td data-k=(format!("twist-{id}-{state}-true-rms")) { (f(*t, 3)) } }
            }
        }
        // One panel per run on one τz scale: on one axis the curve drawn last hid the
        // other wherever they met (the same turn, the same settle).
        div.figs {
            @for (state, s) in &series {
                (time_figure_in(
                    &format!("Twist: τz, wrist loop {state}"),
                    "τz, N·mm",
                    std::slice::from_ref(s),
                    y_range,
                    (420, 300),
                )?)
            }
        }
    })
}

fn bench_part(r: &StoredResult) -> Markup {
    let read = || -> Result<_, String> {
        let t = Columns::of(r, "grasp-bench.csv")?;
        let text = ["model", "varied", "clock"]
            .iter()
            .map(|c| t.text(c))
            .collect::<Result<Vec<_>, _>>()?;
        let nums = [
            "gain_over_lambda",
            "tolerance_n",
            "fps",
            "cycle_rate_hz",
            "late_frames",
            "settle_s",
            "overshoot_n",
            "ss_error_n",
            "true_settle_s",
            "true_ss_error_n",
        ]
        .iter()
        .map(|c| t.num(c))
        .collect::<Result<Vec<_>, _>>()?;
        let rows: Vec<(Vec<String>, Vec<f64>)> = (0..t.len())
            .map(|i| {
                (
                    text.iter().map(|c| c[i].to_owned()).collect(),
                    nums.iter().map(|c| c[i]).collect(),
                )
            })
            .collect();
        Ok(rows)
    };
    let rows = match read() {
        Ok(x) => x,
        Err(e) => return html! { (prov(r)) (unreadable("the benchmark", &e)) },
    };
    html! {
        (prov(r))
        table {
            tr { th.l { "model" } th.l { "varied" } th.l { "clock" } th { "K/Λ" } th { "δ N" } th { "fps" } th { "Hz" } th { "late" } th { "settle s" } th { "overshoot N" } th { "ss error N" } th { "true settle s" } th { "true ss error N" } }
            @for (t, v) in &rows {
                tr {
                    td.l { (t[0]) } td.l { (t[1]) } td.l { (t[2]) }
                    td { (f(v[0], 2)) } td { (f(v[1], 2)) } td { (f(v[2], 0)) } td { (f(v[3], 1)) } td { (f(v[4], 0)) }
                    td { (f(v[5], 3)) } td { (f(v[6], 3)) } td { (f(v[7], 3)) } td { (f(v[8], 3)) } td { (f(v[9], 3)) }
                }
            }
        }
        p.note { "One row per point of the grid: each varies one of K (as a multiple of the model's own Λ_max), δ and the camera rate from the baseline K = 0.75 Λ_max, δ = 0.1 N, 120 Hz. Settle: – never." }
    }
}
