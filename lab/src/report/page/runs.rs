//! The page's runs: the table, each run's detail, the collection figures.

use super::*;

pub(super) fn runs_section(c: &Content) -> Result<Markup, ReportError> {
    let mut per_run = Vec::new();
    for r in &c.runs {
        per_run.push(run_detail(r)?);
    }
    let bench = collection_figures(c)?;
    Ok(html! {
        section #runs {
            h2 { "Runs" }
            @if c.runs.is_empty() {
                (todo("No runs in this database yet. Collect samples (on the simulated rig without a config):",
                      &["softtouch collect --samples 300 --seed 1"]))
            } @else {
                p.prov { "Provenance: each run's seed, and under each run the SHA-256 prefix of its resolved rig and scene TOML and the softtouch version that collected it." }
                table {
                    tr {
                        th { "run" } th.l { "status" } th.l { "scene" } th.l { "medium" } th { "seed" }
                        th { "planned" } th { "ok" } th { "rejected" } th { "retried" } th { "accepted, %" }
                        th { "ok samples/h, run clock" } th { "ok samples/h, wall clock" } th { "wall time, h" } th { "events" } th { "warnings + errors" }
                    }
                    @for d in &c.runs {
                        @let r = &d.row;
                        @let id = r.counts.run_id;
                        @let taken = r.counts.ok + r.counts.rejected;
                        tr {
                            td data-k=(format!("run-{id}-id")) { (id) }
                            td.l { (r.counts.status) }
                            td.l data-k=(format!("run-{id}-scene")) { (r.counts.scene_name) }
                            td.l { (r.counts.medium) }
                            td data-k=(format!("run-{id}-seed")) { (seed_from_sql(r.counts.seed)) }
                            td { (r.counts.samples_planned) }
                            td data-k=(format!("run-{id}-ok")) { (r.counts.ok) }
                            td data-k=(format!("run-{id}-rejected")) { (r.counts.rejected) }
                            td data-k=(format!("run-{id}-retried")) { (r.counts.retried) }
                            td { @if taken > 0 { (f(100.0 * r.counts.ok as f64 / taken as f64, 1)) } @else { "–" } }
                            td data-k=(format!("run-{id}-rate")) { (r.counts.ok_per_run_clock_hour().map_or_else(|| "–".into(), |v| f(v, 0))) }
                            td data-k=(format!("run-{id}-wall-rate")) { (r.counts.ok_per_wall_hour().map_or_else(|| "–".into(), |v| f(v, 0))) }
                            td { (f(r.counts.hours, 3)) }
                            td data-k=(format!("run-{id}-events")) { (r.counts.events) }
                            td { (r.counts.faults) }
                        }
                    }
                }
                @for m in per_run { (m) }
            }
            h3 { "Accuracy against time (bench collection)" }
            (bench)
        }
    })
}

pub(super) fn run_detail(d: &RunData) -> Result<Markup, ReportError> {
    let r = &d.row;
    let id = r.counts.run_id;
    let origin = r
        .counts
        .first_t_ns
        .into_iter()
        .chain(d.timeline.iter().map(|e| e.0))
        .min()
        .unwrap_or(0);
    let hours = |t: i64| (t - origin) as f64 / 3.6e12;
    let progress = [
        Series {
            label: "accepted".into(),
            points: d
                .progress
                .iter()
                .map(|p| (hours(p.0), p.1 as f64))
                .collect(),
            style: SeriesStyle::Line,
        },
        Series {
            label: "rejected".into(),
            points: d
                .progress
                .iter()
                .map(|p| (hours(p.0), p.2 as f64))
                .collect(),
            style: SeriesStyle::Line,
        },
    ];
    let progress_title = format!("Run {id}: samples taken");
    let progress_svg = svg::xy(
        &Xy {
            title: &progress_title,
            x_label: "run clock since the first frame, h",
            y_label: "samples so far",
            series: &progress,
            diagonal: false,
            y_range: None,
            marker_px: 2,
        },
        (560, 300),
    )?;
    let kinds: Vec<String> = d
        .timeline
        .iter()
        .map(|e| e.1.clone())
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let timeline_svg = if d.timeline.is_empty() {
        None
    } else {
        let events: Vec<(f64, usize, String)> = d
            .timeline
            .iter()
            .map(|(t, kind, level)| {
                (
                    hours(*t),
                    kinds.iter().position(|k| k == kind).unwrap_or(0),
                    level.clone(),
                )
            })
            .collect();
        let (lo, hi) = events
            .iter()
            .map(|e| e.0)
            .chain(d.progress.iter().map(|p| hours(p.0)))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
                (a.min(x), b.max(x))
            });
        let rows = kinds.len() as u32;
        Some(svg::timeline(
            &format!("Run {id}: events"),
            &kinds,
            &events,
            (lo, hi),
            (560, (110 + 26 * rows).min(520)),
        )?)
    };
    Ok(html! {
        h3 id=(format!("run-{id}")) { "Run " (id) ": " (r.counts.scene_name) ", " (r.counts.medium) }
        p.prov {
            "seed " (seed_from_sql(r.counts.seed)) " · rig " code { (config_hash(&r.rig_toml)) }
            " · scene " code { (config_hash(&r.scene_toml)) } " · softtouch " (r.software_version)
            " · created " (r.counts.created_at) " · last change " (r.counts.updated_at)
        }
        div.figs {
            (figure(progress_svg))
            (figure(timeline_svg))
        }
        @if d.timeline.len() as i64 >= crate::report::data::MAX_TIMELINE {
            p.note { "The timeline shows the first " (crate::report::data::MAX_TIMELINE) " events with a run-clock time; the counts below have them all." }
        }
        div.figs {
            table {
                tr { th.l { "reject reason" } th { "samples" } }
                @if d.rejects.is_empty() { tr { td.l colspan="2" { "none rejected" } } }
                @for (reason, n) in &d.rejects {
                    tr { td.l { (reason) } td data-k=(format!("run-{id}-reject-{reason}")) { (n) } }
                }
            }
            table {
                tr { th.l { "event" } th.l { "level" } th { "count" } }
                @if d.event_counts.is_empty() { tr { td.l colspan="3" { "no events" } } }
                @for ((kind, level), n) in &d.event_counts {
                    tr { td.l { (kind) } td.l { (level) } td data-k=(format!("run-{id}-event-{kind}-{level}")) { (n) } }
                }
            }
        }
        @if !d.latest.is_empty() {
            table {
                tr { th { "sample" } th.l { "when (UTC)" } th.l { "level" } th.l { "event" } th.l { "message" } }
                @for (sample, at, level, kind, message) in &d.latest {
                    tr {
                        td { (sample.map_or_else(|| "–".to_owned(), |s| s.to_string())) }
                        td.l.nw { (at) } td.l { (level) } td.l { (kind) } td.l { (message) }
                    }
                }
            }
        }
    })
}

pub(super) fn collection_figures(c: &Content) -> Result<Markup, ReportError> {
    let Some(file) = &c.collection else {
        return Ok(todo(
            "No collection benchmark given. Measure label error against samples per hour over settle time and window length, then pass its CSV:",
            &[
                "softtouch bench collection --out bench-out",
                "softtouch report --out report.html --bench-collection bench-out/collection-sweep.csv",
            ],
        ));
    };
    let windows: BTreeSet<u64> = file.points.iter().map(|p| p.window_s.to_bits()).collect();
    let series_of = |pick: fn(&crate::report::csv::CollectionPoint) -> f64| -> Vec<Series> {
        windows
            .iter()
            .map(|&w| {
                let w = f64::from_bits(w);
                let mut pts: Vec<(f64, f64)> = file
                    .points
                    .iter()
                    .filter(|p| p.window_s.to_bits() == w.to_bits())
                    .map(|p| (p.samples_per_hour, pick(p)))
                    .collect();
                pts.sort_by(|a, b| a.0.total_cmp(&b.0));
                Series {
                    label: format!("window {} ms", f(w * 1e3, 0)),
                    points: pts,
                    style: SeriesStyle::LinePoints,
                }
            })
            .collect()
    };
    let force = series_of(|p| p.force_rmse_n);
    let torque = series_of(|p| p.torque_rmse_nmm);
    let fig = |title: &str, y: &str, s: &[Series]| {
        svg::xy(
            &Xy {
                title,
                x_label: "samples per hour (rig clock)",
                y_label: y,
                series: s,
                diagonal: false,
                y_range: None,
                marker_px: 3,
            },
            (560, 340),
        )
    };
    let force_svg = fig("Force label error against speed", "force RMSE, N", &force)?;
    let torque_svg = fig(
        "Torque label error against speed",
        "torque RMSE, N·mm",
        &torque,
    )?;
    Ok(html! {
        p.prov { "From " code { (file.path.display().to_string()) } " (sha256 " code { (file.hash) } "), "
            (file.points.len()) " points; each line is one window length, its points the settle times." }
        div.figs { (figure(force_svg)) (figure(torque_svg)) }
        table {
            tr { th { "settle, s" } th { "window, s" } th { "samples" } th { "accepted" } th { "force RMSE, N" } th { "torque RMSE, N·mm" } th { "samples/h" } }
            @for p in &file.points {
                tr { td { (p.settle_s) } td { (p.window_s) } td { (p.samples) } td { (p.accepted) }
                     td { (f(p.force_rmse_n, 4)) } td { (f(p.torque_rmse_nmm, 3)) } td { (f(p.samples_per_hour, 0)) } }
            }
        }
    })
}
