//! The page's datasets: the table and each dataset's label histograms.

use super::*;

pub(super) fn datasets_section(c: &Content) -> Result<Markup, ReportError> {
    let mut figs = Vec::new();
    for d in &c.datasets {
        figs.push(dataset_figure(d)?);
    }
    Ok(html! {
        section #datasets {
            h2 { "Datasets" }
            @if c.datasets.is_empty() {
                (todo("No datasets yet. Make one over collected runs (seeded 7:1:2 split):",
                      &["softtouch dataset create land-v1 --runs 1 --split 7:1:2 --seed 1"]))
            } @else {
                p.prov { "Provenance: the split seed, the runs drawn on, the SHA-256 prefix of the stored definition (runs, filters, ratio, seed, algorithm) and the softtouch version that made it." }
                table {
                    tr { th.l { "dataset" } th { "samples" } th { "train" } th { "val" } th { "test" } th.l { "ratio" }
                         th { "split seed" } th.l { "runs" } th.l { "definition hash" } th.l { "software" } th.l { "created (UTC)" } }
                    @for d in &c.datasets {
                        @let id = d.dataset_id;
                        tr {
                            td.l data-k=(format!("dataset-{id}-name")) { (d.name) }
                            td data-k=(format!("dataset-{id}-samples")) { (d.sample_count) }
                            td data-k=(format!("dataset-{id}-train")) { (d.splits[0]) }
                            td data-k=(format!("dataset-{id}-val")) { (d.splits[1]) }
                            td data-k=(format!("dataset-{id}-test")) { (d.splits[2]) }
                            td.l { (d.split_ratio) }
                            td { (seed_from_sql(d.seed)) }
                            td.l { (join(d.runs.iter())) }
                            td.l { code { (config_hash(&d.definition_json)) } }
                            td.l { (d.software_version) }
                            td.l { (d.created_at) }
                        }
                    }
                }
                p.note { "Histograms of the labels (the paper's Figure S1e: forces within about ±10 N, torques within about ±600 N·mm)." }
                @for (d, fig) in c.datasets.iter().zip(figs) {
                    h3 { "Dataset " (d.name) }
                    div.figs { (PreEscaped(fig)) }
                }
            }
        }
    })
}

pub(super) fn dataset_figure(d: &DatasetData) -> Result<String, ReportError> {
    let panels: Vec<Panel> = (0..6)
        .map(|axis| Panel {
            x_label: format!("{}, {}", AXES[axis], UNITS[axis]),
            bins: softtouch_collector::plot::bin(&d.values[axis], 40),
        })
        .collect();
    svg::histograms(
        &format!("{}: label histograms ({} samples)", d.name, d.sample_count),
        &panels,
        3,
        (1000, 460),
    )
}
