use super::*;

#[test]
fn bins_cover_every_finite_value_once() {
    let values = [0.0, 0.1, 0.5, 1.0, f64::NAN, f64::INFINITY];
    let bins = bin(&values, 4);
    assert_eq!(bins.len(), 4);
    assert_eq!(bins.iter().map(|b| b.2).sum::<u64>(), 4);
    assert_eq!(bins.last().map(|b| b.2), Some(1)); // the maximum lands in the last bin
    assert!(bin(&[], 4).is_empty());
    assert_eq!(bin(&[2.0, 2.0], 3).iter().map(|b| b.2).sum::<u64>(), 2);
}

#[test]
fn ticks_are_short() {
    let got: Vec<String> = [-5.0, 0.5, 2.25, 0.0, -0.0001, 150.0, 12.5]
        .into_iter()
        .map(|v| format_tick_in(v, f64::INFINITY))
        .collect();
    assert_eq!(got, ["−5", "0.5", "2.25", "0", "−1.0e−4", "150", "12.5"]);
    // A zero tick the axis arithmetic left at -5.6e-17 on a 0.4-wide axis is 0, and a
    // real small value on a small axis keeps its digits.
    assert_eq!(format_tick_in(-5.6e-17, 0.4), "0");
    assert_eq!(format_tick_in(-2.8e-17, 0.6), "0");
    assert_eq!(format_tick_in(0.002, 0.01), "2.0e−3");
}

#[test]
fn ticks_on_a_narrow_axis_differ() {
    // An R² axis of a model benchmark, and an image-MSE axis.
    let r2: Vec<String> = [0.9970, 0.9972, 0.9974, 0.9976]
        .into_iter()
        .map(|v| format_tick_in(v, 0.0014))
        .collect();
    assert_eq!(r2, ["0.997", "0.9972", "0.9974", "0.9976"]);
    let mse: Vec<String> = [1.5e-3, 2.0e-3, 2.5e-3]
        .into_iter()
        .map(|v| format_tick_in(v, 6e-3))
        .collect();
    assert_eq!(mse, ["1.5e−3", "2.0e−3", "2.5e−3"]);
    // A wide axis keeps its short labels; a degenerate span falls back to them.
    assert_eq!(format_tick_in(150.0, 400.0), "150");
    assert_eq!(format_tick_in(0.5, 0.0), "0.5");
    assert_eq!(format_tick_in(0.5, f64::NAN), "0.5");
}

#[test]
fn both_helpers_write_png_files() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let values: Vec<f64> = (0..500)
        .map(|i| (f64::from(i) * 0.37).sin() * 5.0)
        .collect();
    let panels: Vec<HistogramPanel<'_>> = ["a", "b", "c", "d"]
        .iter()
        .map(|t| HistogramPanel {
            title: (*t).into(),
            x_label: "value (N)".into(),
            values: &values,
            bins: 20,
        })
        .collect();
    let hist = dir.path().join("h.png");
    histogram_grid(&hist, Some("test"), &panels, 2, (640, 480)).unwrap_or_else(|e| panic!("{e}"));
    let chart = dir.path().join("c.png");
    let series = [
        Series {
            label: "line".into(),
            points: (0..10).map(|i| (f64::from(i), f64::from(i * i))).collect(),
            style: SeriesStyle::LinePoints,
        },
        Series {
            label: "points".into(),
            points: (0..10).map(|i| (f64::from(i), f64::from(50 - i))).collect(),
            style: SeriesStyle::Points,
        },
    ];
    let spec = XyChart {
        title: "t",
        x_label: "x (s)",
        y_label: "y (N)",
        series: &series,
    };
    xy_chart(&chart, &spec, (480, 360)).unwrap_or_else(|e| panic!("{e}"));
    for p in [hist, chart] {
        let img = image::open(&p).unwrap_or_else(|e| panic!("{e}"));
        assert!(img.width() > 100);
    }
    assert!(histogram_grid(&dir.path().join("x.png"), None, &[], 2, (10, 10)).is_err());
    let bars = dir.path().join("b.png");
    let groups = ["a".to_owned(), "b".to_owned()];
    let series = [BarSeries {
        label: "rate".into(),
        bars: vec![Some((0.5, 0.2, 0.8)), None],
        reference: vec![Some(0.44), None],
        notes: vec![Some("n=10".into())],
    }];
    let chart = BarChart {
        title: "t",
        x_label: None,
        y_label: "success rate",
        groups: &groups,
        series: &series,
        y_range: (0.0, 1.3),
        y_labels_up_to: Some(1.0),
    };
    bar_chart(&bars, &chart, (480, 360)).unwrap_or_else(|e| panic!("{e}"));
    assert!(image::open(&bars).is_ok_and(|i| i.width() == 480));
    let empty = BarChart {
        groups: &[],
        ..chart
    };
    assert!(bar_chart(&dir.path().join("y.png"), &empty, (10, 10)).is_err());
}
