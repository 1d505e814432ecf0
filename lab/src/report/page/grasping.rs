//! The grasping section: every stored grasp session's success table (the one `grasp
//! trials` prints: Wilson 95 % intervals beside the paper's Figure 4f, the failure
//! reasons per cell), its wall time, and a viewer of chosen trials' traces.

use super::*;
use crate::report::grasp_sessions::{GraspData, medium};
use crate::store::GraspTrace;
use base64::Engine as _;

/// What "held" means and how the cells pool, said once above the tables.
fn criterion() -> Markup {
    html! {
        p.note {
            "A trial succeeds when the object is still between the fingers after the lift and the hold (the session's "
            code { "lift_mm" } " and " code { "hold_s" } "). "
            "On the simulator its physics judges (the object held, slipped, crushed, missed; a closed loop that never confirmed its force is a timeout). "
            "On a rig the rig judge reads gOBJ, the final position and the finger's estimate, and the operator confirms or corrects it (a crush only a person sees). "
            "A device error is a device fault. Each cell pools the trials of one σ, medium, object and mode; the "
            em { "all" } " rows pool the objects, and the paper's rates (Figure 4f) stand beside those only. "
            "A trial refused before anything moved (a perturbed pose outside the rig's workspace) counts in no cell. Intervals: Wilson 95 %."
        }
    }
}

/// The grasping section.
pub(super) fn grasping_section(c: &Content) -> Result<Markup, ReportError> {
    let sessions = c.grasp.iter().map(session).collect::<Result<Vec<_>, _>>()?;
    Ok(html! {
        section #grasping {
            h2 { "Grasping" }
            @if c.grasp.is_empty() {
                (todo_in(c, "No grasp sessions in this database yet. The trials are stored as grasp sessions as they run:",
                      &["softtouch grasp trials --model {model} --trials 10 --sigma-mm 5",
                        "softtouch grasp trials --model {model} --rig lab.toml --objects bottle,ball"]))
            } @else {
                (criterion())
                @for s in &sessions { (s) }
            }
        }
    })
}

fn pct(v: Option<f64>) -> String {
    v.map_or_else(|| "–".to_owned(), |v| format!("{:.0} %", 100.0 * v))
}

/// The image tares a session read its scenes through, for people (`None`: none).
fn tare_text(p: &crate::grasp::trials::TrialPlan) -> Option<String> {
    let tares: Vec<String> = p
        .scene_tares
        .iter()
        .flatten()
        .map(|t| {
            format!(
                "scale {:.3} against the rest frames of dataset `{}`",
                t.tare.scale, t.against
            )
        })
        .collect();
    (!tares.is_empty()).then(|| tares.join("; "))
}

fn session(g: &GraspData) -> Result<Markup, ReportError> {
    let id = g.session.session_id;
    let planned = g.plan.as_ref().map_or(0, |p| {
        p.objects.len() * p.modes.len() * p.trials as usize * p.sigmas_mm.len() * g.media.len()
    });
    let sigma = |i: u32| {
        g.plan
            .as_ref()
            .and_then(|p| p.sigmas_mm.get(i as usize))
            .map_or_else(|| "?".to_owned(), |s| format!("{s}"))
    };
    let figures = g
        .viewed
        .iter()
        .map(|(r, t)| trial_figure(g, r, t.as_ref()))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(html! {
        h3 #(format!("grasp-session-{id}")) { "Session " (id) ": " (g.kind()) }
        p.prov {
            "Model " code { (g.session.model) }
            @if let Some(sha) = &g.session.model_sha256 { " (sha256 " code { (&sha[..12.min(sha.len())]) } ")" }
            ", seed " (g.session.seed) ", started " (g.session.created_at) ", "
            span data-k=(format!("grasp-{id}-stored")) { (g.rows.len()) } " of " (planned) " trials stored"
            @if let Some(p) = &g.plan {
                "; σ " (join(p.sigmas_mm.iter())) " mm, lift " (p.lift_mm) " mm, hold " (p.hold_s) " s, F_ref " (p.target_n) " N ± " (p.tolerance_n) " N"
                @if !p.sets.is_empty() {
                    "; scene values set: "
                    span data-k=(format!("grasp-{id}-sets")) { (p.sets.join(", ")) }
                }
                @if let Some(tare) = tare_text(p) {
                    "; water frames read through an image tare: "
                    span data-k=(format!("grasp-{id}-tare")) { (tare) }
                } @else if g.media.contains(&softtouch_schemas::Medium::Water) {
                    "; water frames read as they come (no image tare)"
                }
            }
            "."
        }
        @for p in &g.problems { p.todo { "Could not read: " (p) } }
        table {
            tr { th { "σ mm" } th.l { "medium" } th.l { "object" } th.l { "mode" } th { "held/n" } th { "rate" } th { "Wilson 95 %" } th { "paper" } th { "grip max" } th.l { "failures" } }
            @for c in &g.cells {
                @let object = c.object.clone().unwrap_or_else(|| "all".into());
                tr {
                    td { (sigma(c.sigma_index)) }
                    td.l { (scene_label(g, c.medium, c.scene_index)) }
                    td.l { @if c.object.is_none() { b { "all" } } @else { (object) } }
                    td.l { (c.mode.as_str()) }
                    td data-k=(format!("grasp-{id}-{}-{}-{}-{}", c.sigma_index, c.scene_index, object, c.mode.as_str())) { (c.held) "/" (c.trials) }
                    td { (pct(c.rate())) }
                    td.nw { "[" (format!("{:.0}", 100.0 * c.interval[0])) ", " (format!("{:.0}", 100.0 * c.interval[1])) "] %" }
                    td { (pct(c.paper())) }
                    td data-k=(format!("grasp-{id}-{}-{}-{}-{}-grip", c.sigma_index, c.scene_index, object, c.mode.as_str())) { (c.grip_text()) }
                    td.l { (c.failures_text()) }
                }
            }
        }
        @for (i, cap) in g.caps.iter().enumerate() {
            @if let Some(p) = &g.plan {
                p.note data-k=(format!("grasp-{id}-cap-{i}")) { (cap.describe(p.target_n)) ". The paper's closed loop: " (format!("{:.0} %", 100.0 * crate::grasp::trials::paper_rate(cap.medium, softtouch_grasp::Mode::Closed))) "." }
            }
        }
        p.note { "Grip max: the largest true grip force of the cell's trials where the simulator knows it (N); on a rig, where no true force is known, the deepest closing past the calibrated first touch (mm). Every closed loop is bounded by its calibration's squeeze (docs/grasping.md)." }
        @let pairs = g.plan.as_ref().map(|p| crate::grasp::trials::table::paired(p, &g.media, &g.rows)).unwrap_or_default();
        @if !pairs.is_empty() {
            p.note { "Open against closed loop on the same perturbations: trials pair by object and trial number, which draw the same grasp-point offset in both modes; McNemar's exact test (two-sided) asks whether the pairs that differ lean one way more than chance." }
            table {
                tr { th { "σ mm" } th.l { "medium" } th { "pairs" } th { "held both" } th { "open only" } th { "closed only" } th { "neither" } th { "McNemar p" } }
                @for p in &pairs {
                    tr {
                        td { (sigma(p.sigma_index)) } td.l { (scene_label(g, p.medium, p.scene_index)) } td { (p.pairs) } td { (p.both) }
                        td { (p.open_only) } td { (p.closed_only) } td { (p.neither) }
                        td data-k=(format!("grasp-{id}-{}-{}-mcnemar", p.sigma_index, p.scene_index)) { (format!("{:.4}", p.p)) }
                    }
                }
            }
        }
        div.figs { (rates_figure(g, false)?) (rates_figure(g, true)?) (sweep_figure(g)?) }
        (wall_time(g))
        @if !figures.is_empty() {
            p.note {
                "Trials drawn: the first failure of each kind and the first success of each medium and mode, "
                "with the finger's camera frames at first contact, confirmation, lift and end (those that happened; thumbnails stored with the trace)."
            }
            div.figs { @for f in figures { (f) } }
        }
    })
}

/// A scene's medium, and in a swept session the value it ran at.
fn scene_label(g: &GraspData, m: softtouch_schemas::Medium, scene_index: u32) -> String {
    match g
        .plan
        .as_ref()
        .and_then(|p| p.sweep.as_ref())
        .and_then(|s| Some((s.path.as_str(), s.value_of(scene_index)?)))
    {
        Some((path, v)) => format!("{}, {path} = {v}", medium(m)),
        None => medium(m).to_owned(),
    }
}

/// In a session that swept a scene value: success against it (all objects, the first
/// σ), one bar per medium and mode with its Wilson interval and n.
fn sweep_figure(g: &GraspData) -> Result<Markup, ReportError> {
    let Some(sweep) = g.plan.as_ref().and_then(|p| p.sweep.as_ref()) else {
        return Ok(html! {});
    };
    let per = sweep.per_value.max(1);
    let pooled: Vec<&crate::grasp::trials::table::Cell> = g
        .cells
        .iter()
        .filter(|c| c.object.is_none() && c.sigma_index == 0)
        .collect();
    let mut keys: Vec<(u32, softtouch_schemas::Medium, softtouch_grasp::Mode)> = Vec::new();
    for c in &pooled {
        if !keys
            .iter()
            .any(|k| k.0 == c.scene_index % per && k.2 == c.mode)
        {
            keys.push((c.scene_index % per, c.medium, c.mode));
        }
    }
    let series: Vec<svg::RateValues> = keys
        .iter()
        .map(|(base, m, mode)| {
            let mut values = vec![None; sweep.values.len()];
            let mut notes = vec![None; sweep.values.len()];
            for c in pooled
                .iter()
                .filter(|c| c.scene_index % per == *base && c.mode == *mode)
            {
                let (Some(i), Some(rate)) = (sweep.value_index(c.scene_index), c.rate()) else {
                    continue;
                };
                values[i] = Some((rate, c.interval[0], c.interval[1]));
                notes[i] = Some(format!("n={}", c.trials));
            }
            (format!("{} {}", medium(*m), mode.as_str()), values, notes)
        })
        .collect();
    let width = (220 + 90 * sweep.values.len() * keys.len().max(1)).clamp(460, 1100) as u32;
    Ok(figure(Some(svg::rate_bars(
        &format!(
            "Session {}: success against {} (objects pooled)",
            g.session.session_id, sweep.path
        ),
        &sweep.path,
        &(0..sweep.values.len())
            .map(|i| sweep.value_label(i))
            .collect::<Vec<_>>(),
        &series,
        (width, 340),
    )?)))
}

/// Success per object (the first σ, and in a swept session the first value), or per
/// σ (all objects pooled; drawn only with more than one σ), one bar per medium and
/// mode, with its Wilson interval and n.
fn rates_figure(g: &GraspData, by_sigma: bool) -> Result<Markup, ReportError> {
    let sigmas: Vec<u32> = {
        let mut v: Vec<u32> = g.cells.iter().map(|c| c.sigma_index).collect();
        v.dedup();
        v.sort_unstable();
        v.dedup();
        v
    };
    if g.cells.is_empty() || (by_sigma && sigmas.len() < 2) {
        return Ok(html! {});
    }
    let first = sigmas[0];
    let cells: Vec<&crate::grasp::trials::table::Cell> = g
        .cells
        .iter()
        .filter(|c| {
            let first_value = g
                .plan
                .as_ref()
                .and_then(|p| p.sweep.as_ref())
                .is_none_or(|s| s.value_index(c.scene_index) == Some(0));
            if by_sigma {
                c.object.is_none() && first_value
            } else {
                c.sigma_index == first && first_value
            }
        })
        .collect();
    let category = |c: &crate::grasp::trials::table::Cell| -> String {
        if by_sigma {
            g.plan
                .as_ref()
                .and_then(|p| p.sigmas_mm.get(c.sigma_index as usize))
                .map_or_else(|| "?".into(), |s| crate::grasp::trials::sigma_label(*s))
        } else {
            c.object.clone().unwrap_or_else(|| "all".into())
        }
    };
    let mut categories: Vec<String> = Vec::new();
    let mut series_keys: Vec<(String, String)> = Vec::new();
    for c in &cells {
        let cat = category(c);
        if !categories.contains(&cat) {
            categories.push(cat);
        }
        let key = (medium(c.medium).to_owned(), c.mode.as_str().to_owned());
        if !series_keys.contains(&key) {
            series_keys.push(key);
        }
    }
    let series: Vec<svg::RateValues> = series_keys
        .iter()
        .map(|(m, mode)| {
            let mut values = vec![None; categories.len()];
            let mut notes = vec![None; categories.len()];
            for c in cells
                .iter()
                .filter(|c| medium(c.medium) == m && c.mode.as_str() == mode)
            {
                let Some(i) = categories.iter().position(|x| *x == category(c)) else {
                    continue;
                };
                if let Some(rate) = c.rate() {
                    values[i] = Some((rate, c.interval[0], c.interval[1]));
                    notes[i] = Some(format!("n={}", c.trials));
                }
            }
            (format!("{m} {mode}"), values, notes)
        })
        .collect();
    let title = if by_sigma {
        format!(
            "Session {}: success against σ (objects pooled)",
            g.session.session_id
        )
    } else {
        format!("Session {}: success per object", g.session.session_id)
    };
    let width = (220 + 90 * categories.len() * series_keys.len().max(1)).clamp(460, 1100) as u32;
    Ok(figure(Some(svg::rate_bars(
        &title,
        if by_sigma {
            "grasp-point perturbation σ"
        } else {
            "object"
        },
        &categories,
        &series,
        (width, 340),
    )?)))
}

/// Wall time per medium and mode.
fn wall_time(g: &GraspData) -> Markup {
    let mut groups: Vec<(String, String)> = Vec::new();
    for r in &g.rows {
        let k = (r.medium.clone(), r.key.mode.clone());
        if !groups.contains(&k) {
            groups.push(k);
        }
    }
    html! {
        table {
            tr { th.l { "medium" } th.l { "mode" } th { "trials" } th { "mean s" } th { "max s" } }
            @for (m, mode) in &groups {
                @let w: Vec<f64> = g.rows.iter().filter(|r| &r.medium == m && &r.key.mode == mode).map(|r| r.wall_s).collect();
                tr {
                    td.l { (m) } td.l { (mode) } td { (w.len()) }
                    td { (f(w.iter().sum::<f64>() / w.len().max(1) as f64, 3)) }
                    td { (f(w.iter().copied().fold(0.0, f64::max), 3)) }
                }
            }
        }
    }
}

/// Points of a chart, (x, y).
type Points = Vec<(f64, f64)>;

/// The window the trial viewer averages the estimate over, s.
const ESTIMATE_WINDOW_S: f64 = 0.1;

/// `values` against `t_s` in windows of `window_s`: each window's mean at its mean
/// time, and the band of each window's least to greatest value (the upper edge forward,
/// the lower edge back). Non-finite values are left out; a window with none has no
/// point. Empty input gives empty output.
fn windowed_mean_and_range(t_s: &[f32], values: &[f32], window_s: f64) -> (Points, Points) {
    // (window index, Σt, Σv, n, min, max), in time order.
    let mut windows: Vec<(i64, f64, f64, u32, f64, f64)> = Vec::new();
    for (&t, &v) in t_s.iter().zip(values) {
        let (t, v) = (f64::from(t), f64::from(v));
        if !(t.is_finite() && v.is_finite()) || window_s <= 0.0 {
            continue;
        }
        #[allow(clippy::cast_possible_truncation)] // a trace lasts seconds
        let k = (t / window_s).floor() as i64;
        match windows.last_mut() {
            Some(w) if w.0 == k => {
                w.1 += t;
                w.2 += v;
                w.3 += 1;
                w.4 = w.4.min(v);
                w.5 = w.5.max(v);
            }
            _ => windows.push((k, t, v, 1, v, v)),
        }
    }
    let at = |w: &(i64, f64, f64, u32, f64, f64)| w.1 / f64::from(w.3);
    let mean = windows
        .iter()
        .map(|w| (at(w), w.2 / f64::from(w.3)))
        .collect();
    let band = windows
        .iter()
        .map(|w| (at(w), w.5))
        .chain(windows.iter().rev().map(|w| (at(w), w.4)))
        .collect();
    (mean, band)
}

/// One trial's trace: the estimate (and the truth, on the simulator) against time with
/// the target band, and the commanded and measured positions.
fn trial_figure(
    g: &GraspData,
    r: &crate::store::GraspTrialRow,
    trace: Option<&GraspTrace>,
) -> Result<Markup, ReportError> {
    let verdict = r.reason.as_deref().unwrap_or("held");
    let title = format!(
        "{} {} #{} ({}, σ {} mm): {verdict}",
        r.key.object,
        r.key.mode,
        r.key.trial,
        r.medium,
        r.sigma_m * 1000.0
    );
    let Some(t) = trace.filter(|t| !t.t_s.is_empty()) else {
        return Ok(html! { p.note { (title) ": no trace stored" } });
    };
    let pts = |v: &[f32]| -> Vec<(f64, f64)> {
        t.t_s
            .iter()
            .zip(v)
            .map(|(x, y)| (f64::from(*x), f64::from(*y)))
            .collect()
    };
    // The closed loop dithers by a count around F_ref, and the estimate with it, frame
    // by frame: drawn raw, 120 points a second fill a solid block. Its mean over
    // 0.1 s is the trace a person follows; its range over the same windows the band.
    let (mean, band) = windowed_mean_and_range(&t.t_s, &t.estimate_n, ESTIMATE_WINDOW_S);
    let mut force = vec![
        Series {
            label: format!("estimate, mean over {} s", ESTIMATE_WINDOW_S),
            points: mean,
            style: SeriesStyle::Line,
        },
        Series {
            label: "estimate, its range".into(),
            points: band,
            style: SeriesStyle::Band,
        },
    ];
    if t.true_n.iter().any(|v| v.is_finite()) {
        force.push(Series {
            label: "true (simulator)".into(),
            points: pts(&t.true_n),
            style: SeriesStyle::Line,
        });
    }
    let end = f64::from(t.t_s.last().copied().unwrap_or(0.0));
    // When the loop confirmed and the lift started: vertical marks from the frames'
    // moments (a session stored before frames were kept has none).
    let (lo, hi) = t
        .estimate_n
        .iter()
        .chain(&t.true_n)
        .copied()
        .filter(|v| v.is_finite())
        .fold((0.0_f64, 0.0_f64), |(a, b), v| {
            (a.min(f64::from(v)), b.max(f64::from(v)))
        });
    // The confirmation is marked where the loop confirmed (the stored time the CSV and
    // the position chart's title give); its frame is the newest at that moment.
    let confirmed = r.confirmed_after_s.or_else(|| {
        t.frames
            .iter()
            .find(|f| f.moment == "confirmed")
            .map(|f| f.t_s)
    });
    let lifted = t
        .frames
        .iter()
        .find(|f| f.moment == "lifted")
        .map(|f| f.t_s);
    for (moment, at) in [("confirmed", confirmed), ("lifted", lifted)] {
        let Some(at) = at else { continue };
        force.push(Series {
            label: format!("{moment} ({at:.2} s)"),
            points: vec![(at, lo), (at, hi.max(lo + 0.1))],
            style: SeriesStyle::Line,
        });
    }
    if let Some(p) = g.plan.as_ref().filter(|_| r.key.mode == "closed") {
        // The target's band, one series (the palette has six colours: seven series
        // would give two the same).
        let (lo, hi) = (p.target_n - p.tolerance_n, p.target_n + p.tolerance_n);
        force.push(Series {
            label: "F_ref ± δ".into(),
            points: vec![(0.0, hi), (end, hi), (end, lo), (0.0, lo)],
            style: SeriesStyle::Band,
        });
    }
    let counts = |v: &[u8]| -> Vec<(f64, f64)> {
        t.t_s
            .iter()
            .zip(v)
            .map(|(x, y)| (f64::from(*x), f64::from(*y)))
            .collect()
    };
    let positions = [
        Series {
            label: "requested".into(),
            points: counts(&t.request_count),
            style: SeriesStyle::Line,
        },
        Series {
            label: "measured".into(),
            points: counts(&t.measured_count),
            style: SeriesStyle::Line,
        },
    ];
    let force_svg = svg::xy(
        &Xy {
            title: &title,
            x_label: "time since the trial's first cycle, s",
            y_label: "grip force, N",
            series: &force,
            diagonal: false,
            y_range: None,
            marker_px: 2,
        },
        (460, 280),
    )?;
    let position_title = format!(
        "{} {} #{}: position{}",
        r.key.object,
        r.key.mode,
        r.key.trial,
        r.confirmed_after_s
            .map_or_else(String::new, |s| format!(" (confirmed after {s:.2} s)"))
    );
    let position_svg = svg::xy(
        &Xy {
            title: &position_title,
            x_label: "time since the trial's first cycle, s",
            y_label: "gripper position, counts",
            series: &positions,
            diagonal: false,
            y_range: None,
            marker_px: 2,
        },
        (460, 280),
    )?;
    Ok(html! {
        div.trial {
            (figure(force_svg)) (figure(position_svg))
            @if !t.frames.is_empty() {
                div.frames {
                    @for f in &t.frames {
                        figure.frame {
                            img src=(format!("data:image/png;base64,{}", base64::engine::general_purpose::STANDARD.encode(&f.png)))
                                alt=(format!("the finger's frame at {}", f.moment)) width="160";
                            figcaption { (f.moment) ", " (format!("{:.2}", f.t_s)) " s" }
                        }
                    }
                }
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::windowed_mean_and_range;

    #[test]
    fn a_dithering_estimate_becomes_its_mean_and_range() {
        // 120 Hz for 0.5 s, alternating 1.9 and 2.1 N: five windows of mean 2 N.
        let t: Vec<f32> = (0..60).map(|i| i as f32 / 120.0).collect();
        let v: Vec<f32> = (0..60)
            .map(|i| if i % 2 == 0 { 1.9 } else { 2.1 })
            .collect();
        let (mean, band) = windowed_mean_and_range(&t, &v, 0.1);
        assert_eq!(mean.len(), 5);
        assert!(mean.iter().all(|(_, m)| (m - 2.0).abs() < 1e-6), "{mean:?}");
        assert!(mean.windows(2).all(|w| w[0].0 < w[1].0), "in time order");
        assert_eq!(band.len(), 10);
        assert!(band[..5].iter().all(|(_, hi)| (hi - 2.1).abs() < 1e-6));
        assert!(band[5..].iter().all(|(_, lo)| (lo - 1.9).abs() < 1e-6));
        // The band closes back along the lower edge.
        assert!((band[5].0 - band[4].0).abs() < 1e-12 && (band[9].0 - band[0].0).abs() < 1e-12);
    }

    #[test]
    fn empty_constant_and_non_finite_traces() {
        assert_eq!(
            windowed_mean_and_range(&[], &[], 0.1),
            (Vec::new(), Vec::new())
        );
        let (mean, band) = windowed_mean_and_range(&[0.0, 0.05, 0.2], &[1.0, 1.0, 1.0], 0.1);
        assert_eq!(mean.len(), 2);
        assert!(
            mean.iter()
                .chain(&band)
                .all(|(_, v)| (v - 1.0).abs() < 1e-12)
        );
        let (mean, band) =
            windowed_mean_and_range(&[0.0, 0.01, f32::NAN], &[f32::NAN, 3.0, 4.0], 0.1);
        assert_eq!(mean, vec![(f64::from(0.01_f32), 3.0)]);
        assert_eq!(band.len(), 2);
        // No window: nothing drawn, never a division by zero.
        assert_eq!(
            windowed_mean_and_range(&[0.0], &[1.0], 0.0),
            (Vec::new(), Vec::new())
        );
    }
}
