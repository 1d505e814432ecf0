//! `softtouch bench train`'s figures: the peer's JSON line read, medians per
//! configuration, the terminal's table and `bench-train.csv` (with the host and the
//! peer's version on every row).

use softtouch_trainer::train::TrainBench;

/// The PyTorch peer's figures for one configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct TorchRun {
    /// Training images/s over the timed steps.
    pub images_per_s: f64,
    /// Cores it kept busy.
    pub cores_used: Option<f64>,
    /// PyTorch's version, as the peer reports it.
    pub version: Option<String>,
}

/// One configuration's measurements.
#[derive(Debug)]
pub struct Row {
    /// Input size, px.
    pub size: usize,
    /// Encoder width.
    pub width: usize,
    /// softtouch's measurements.
    pub ours: Vec<TrainBench>,
    /// The peer's, interleaved.
    pub torch: Vec<TorchRun>,
}

/// The median of the finite values, `None` without one.
#[must_use]
pub fn median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

/// Reads the peer's JSON line: its images/s over the total time of the timed steps.
///
/// # Errors
/// No JSON line, one that does not parse, or no positive images/s.
pub fn parse_torch(stdout: &str) -> Result<TorchRun, String> {
    let line = stdout
        .lines()
        .rev()
        .find(|l| l.trim_start().starts_with('{'))
        .ok_or_else(|| "no JSON line in its output".to_owned())?;
    let v: serde_json::Value =
        serde_json::from_str(line).map_err(|e| format!("its JSON line does not parse: {e}"))?;
    let images_per_s = v
        .get("train_img_per_s_total")
        .and_then(serde_json::Value::as_f64)
        .filter(|x| x.is_finite() && *x > 0.0)
        .ok_or_else(|| "its JSON has no positive train_img_per_s_total".to_owned())?;
    Ok(TorchRun {
        images_per_s,
        cores_used: v
            .get("train_cores_used")
            .and_then(serde_json::Value::as_f64),
        version: v
            .get("torch")
            .and_then(serde_json::Value::as_str)
            .map(str::to_owned),
    })
}

/// The medians of one row: (img/s, GFLOP/s, cores, phases ms, PyTorch img/s, its cores).
struct Medians {
    images_per_s: f64,
    gflop_per_s: f64,
    cores: Option<f64>,
    phases: [f64; 4],
    torch: Option<f64>,
    torch_cores: Option<f64>,
}

fn medians(row: &Row) -> Medians {
    let m = |f: &dyn Fn(&TrainBench) -> f64| {
        median(row.ours.iter().map(f).collect()).unwrap_or(f64::NAN)
    };
    Medians {
        images_per_s: m(&|b| b.images_per_s),
        gflop_per_s: m(&|b| b.gflop_per_s),
        cores: median(row.ours.iter().filter_map(|b| b.cores_used).collect()),
        phases: [
            m(&|b| b.phase_ms.batch),
            m(&|b| b.phase_ms.forward),
            m(&|b| b.phase_ms.backward),
            m(&|b| b.phase_ms.optimiser),
        ],
        torch: median(row.torch.iter().map(|t| t.images_per_s).collect()),
        torch_cores: median(row.torch.iter().filter_map(|t| t.cores_used).collect()),
    }
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.filter(|x| x.is_finite())
        .map_or_else(|| "–".to_owned(), |x| format!("{x:.digits$}"))
}

/// The terminal's table, medians per configuration.
#[must_use]
pub fn render(rows: &[Row], batch: usize) -> String {
    let mut s = format!(
        "\ntraining, batch {batch} (medians; phases in ms per step):\ninput/width   img/s  GFLOP/s  cores   batch  forward  backward  optimiser   PyTorch img/s  cores   ratio\n"
    );
    for row in rows {
        let m = medians(row);
        let ratio = m.torch.map(|t| m.images_per_s / t);
        s.push_str(&format!(
            "{:<12} {:>6.0} {:>8.1} {:>6} {:>7.2} {:>8.2} {:>9.2} {:>10.2}   {:>13} {:>6} {:>7}\n",
            format!("{}×{}/{}", row.size, row.size, row.width),
            m.images_per_s,
            m.gflop_per_s,
            opt(m.cores, 2),
            m.phases[0],
            m.phases[1],
            m.phases[2],
            m.phases[3],
            opt(m.torch, 0),
            opt(m.torch_cores, 2),
            opt(ratio, 2),
        ));
    }
    if let Some(v) = rows
        .iter()
        .flat_map(|r| &r.torch)
        .find_map(|t| t.version.clone())
    {
        s.push_str(&format!("the peer ran PyTorch {v}\n"));
    }
    s
}

/// `bench-train.csv`: medians per configuration, with the host and the peer's version
/// on every row (a figure is read with where it was taken).
#[must_use]
pub fn csv_text(rows: &[Row], host: &crate::host::Host) -> String {
    let mut s = String::from(
        "size_px,width,images_per_s,gflop_per_s,cores_used,batch_ms,forward_ms,backward_ms,optimiser_ms,torch_images_per_s,torch_cores_used,ratio,host_cpu,simd,torch_version\n",
    );
    let o = |v: Option<f64>| {
        v.filter(|x| x.is_finite())
            .map_or(String::new(), |x| x.to_string())
    };
    for row in rows {
        let m = medians(row);
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            row.size,
            row.width,
            m.images_per_s,
            m.gflop_per_s,
            o(m.cores),
            m.phases[0],
            m.phases[1],
            m.phases[2],
            m.phases[3],
            o(m.torch),
            o(m.torch_cores),
            o(m.torch.map(|t| m.images_per_s / t)),
            host.cpu.replace(',', " "),
            host.simd,
            row.torch
                .iter()
                .find_map(|t| t.version.clone())
                .unwrap_or_default(),
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_peers_json_line_is_read_or_refused_by_name() {
        let good = "loading\n{\"size\": 32, \"train_img_per_s_total\": 2666.5, \"train_cores_used\": 1.9}\n";
        let t = parse_torch(good).expect("parses");
        assert!((t.images_per_s - 2666.5).abs() < 1e-9 && t.cores_used == Some(1.9));
        assert_eq!(t.version, None);
        let v = parse_torch("{\"train_img_per_s_total\": 1.0, \"torch\": \"2.15.0+cu132\"}")
            .expect("parses");
        assert_eq!(v.version.as_deref(), Some("2.15.0+cu132"));
        for (bad, why) in [
            ("", "no JSON line"),
            ("{not json", "does not parse"),
            ("{\"train_img_per_s\": 1.0}", "train_img_per_s_total"),
            ("{\"train_img_per_s_total\": -3}", "train_img_per_s_total"),
            (
                "{\"train_img_per_s_total\": \"fast\"}",
                "train_img_per_s_total",
            ),
        ] {
            let Err(e) = parse_torch(bad) else {
                panic!("{bad}: accepted");
            };
            assert!(e.contains(why), "{bad}: {e}");
        }
    }

    #[test]
    fn medians_skip_what_is_not_a_number() {
        assert_eq!(median(vec![]), None);
        assert_eq!(median(vec![f64::NAN]), None);
        assert_eq!(median(vec![3.0, f64::NAN, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(vec![4.0, 1.0]), Some(2.5));
    }
}
