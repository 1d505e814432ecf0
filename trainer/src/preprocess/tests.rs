use super::*;

/// HSV of an RGB8 pixel: hue in degrees [0, 360), saturation and value in [0, 1];
/// the definition [`Preprocess::is_finger`] thresholds.
fn hsv(r: u8, g: u8, b: u8) -> (f32, f32, f32) {
    // Which channel is largest is decided on the integers (exact).
    let max_u = r.max(g).max(b);
    let min_u = r.min(g).min(b);
    let max = f32::from(max_u);
    let delta = f32::from(max_u - min_u);
    let value = max / 255.0;
    if max_u == 0 || max_u == min_u {
        return (0.0, 0.0, value);
    }
    (hue_deg(r, g, b, max_u, delta), delta / max, value)
}

/// A window across 0° with no saturation or value threshold: greys pass.
fn reds_and_greys() -> Preprocess {
    Preprocess {
        hue_min_deg: 340.0,
        hue_max_deg: 20.0,
        saturation_min: 0.0,
        value_min: 0.0,
        ..Preprocess::default()
    }
}

fn solid(w: usize, h: usize, px: [u8; 3]) -> Vec<u8> {
    px.iter().copied().cycle().take(w * h * 3).collect()
}

#[test]
fn hues_of_primary_and_finger_colours() {
    let close = |a: f32, b: f32| (a - b).abs() < 0.5;
    assert!(close(hsv(255, 0, 0).0, 0.0));
    assert!(close(hsv(0, 255, 0).0, 120.0));
    assert!(close(hsv(0, 0, 255).0, 240.0));
    assert!(close(hsv(255, 0, 128).0, 330.0));
    let p = Preprocess::default();
    assert!(p.is_finger(230, 130, 40), "orange finger in air");
    assert!(p.is_finger(180, 150, 50), "yellow finger through water");
    assert!(!p.is_finger(30, 45, 70), "dark blue background");
    assert!(!p.is_finger(200, 200, 200), "grey bubble");
}

#[test]
fn all_black_and_all_white_images_give_zeros_and_finite_values() {
    let p = Preprocess::default();
    for px in [[0, 0, 0], [255, 255, 255]] {
        let out = p
            .apply(640, 480, &solid(640, 480, px))
            .expect("valid image");
        assert_eq!(out.len(), p.size_px * p.size_px);
        assert!(
            out.iter().all(|v| *v == 0.0),
            "{px:?} holds no finger pixels"
        );
    }
    let out = p
        .apply(640, 480, &solid(640, 480, [255, 128, 0]))
        .expect("valid image");
    assert!(out.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)));
    assert!((out[0] - (255.0 + 128.0) / (3.0 * 255.0)).abs() < 1e-5);
}

#[test]
fn box_filter_keeps_the_mean_and_handles_tiny_and_odd_images() {
    let p = Preprocess {
        channels: 3,
        size_px: 8,
        ..Preprocess::default()
    };
    // Left half finger-orange, right half background: the left half of the output
    // is orange, the right half zero.
    let (w, h) = (80, 60);
    let mut rgb = solid(w, h, [20, 30, 60]);
    for y in 0..h {
        for x in 0..w / 2 {
            rgb[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[250, 140, 20]);
        }
    }
    let out = p.apply(w, h, &rgb).expect("valid image");
    assert!((out[0] - 250.0 / 255.0).abs() < 1e-5);
    assert!(out[7].abs() < 1e-6);
    // One channel: the mean of the kept pixels' three channels.
    let grey = Preprocess { channels: 1, ..p }
        .apply(w, h, &rgb)
        .expect("valid image");
    assert!((grey[0] - 410.0 / 3.0 / 255.0).abs() < 1e-6, "{}", grey[0]);
    assert!(grey[7].abs() < 1e-6);
    // Images smaller than the output and of odd sizes still fill every value.
    for (w, h) in [(1, 1), (3, 5), (7, 2)] {
        let out = p.apply(w, h, &solid(w, h, [250, 140, 20])).expect("valid");
        for (plane, value) in out.chunks(64).zip([250.0, 140.0, 20.0]) {
            assert!(plane.iter().all(|v| (*v - value / 255.0).abs() < 1e-6));
        }
    }
}

#[test]
fn the_table_gives_the_same_output_and_the_same_errors() {
    // Every colour family, in a frame whose size the output does not divide.
    let (w, h) = (203, 151);
    let rgb: Vec<u8> = (0..w * h * 3)
        .map(|i| ((i * 2_654_435_761usize) >> 7) as u8)
        .collect();
    for (channels, signal) in [
        (1, Signal::Brightness),
        (1, Signal::Chroma),
        (3, Signal::Brightness),
    ] {
        let p = Preprocess {
            channels,
            size_px: 32,
            signal,
            ..Preprocess::default()
        };
        let table = FingerTable::new(&p);
        let direct = p.apply(w, h, &rgb).expect("valid");
        let looked_up = table.apply(w, h, &rgb).expect("valid");
        let mut split = vec![0.0; p.input_len()];
        table
            .apply_into_on(w, h, &rgb, &mut split, Some(&ScopedThread))
            .expect("valid");
        assert_eq!(looked_up, split, "two threads give the same output");
        assert!(direct.iter().any(|v| *v > 0.0));
        assert!(
            direct
                .iter()
                .zip(&looked_up)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
        assert!(table.apply(10, 10, &[0; 299]).is_err());
        assert!(table.apply(0, 10, &[]).is_err());
    }
}

#[test]
fn malformed_inputs_are_errors_not_panics() {
    let p = Preprocess::default();
    assert!(p.apply(0, 10, &[]).is_err());
    assert!(p.apply(10, 10, &[0; 299]).is_err());
    let mut short = vec![0.0; 10];
    assert!(p.apply_into(1, 1, &[0, 0, 0], &mut short).is_err());
    let bad = Preprocess {
        size_px: 48,
        channels: 2,
        hue_min_deg: f32::NAN,
        ..Preprocess::default()
    };
    assert_eq!(bad.problems().len(), 3, "{:?}", bad.problems());
    assert!(Preprocess::default().problems().is_empty());
    let rgb_chroma = Preprocess {
        channels: 3,
        signal: Signal::Chroma,
        ..Preprocess::default()
    };
    let p = rgb_chroma.problems();
    assert!(
        p.len() == 1 && p[0].contains("signal chroma with 3 channels"),
        "{p:?}"
    );
    assert_eq!("chroma".parse::<Signal>(), Ok(Signal::Chroma));
    let e = "value".parse::<Signal>().expect_err("unknown");
    assert!(
        e.contains("`value`") && e.contains("`brightness` or `chroma`"),
        "{e}"
    );
}

/// White light added alike to every channel (caustics) moves brightness and
/// leaves chroma as it was, decisions included.
#[test]
fn chroma_is_blind_to_white_light_added_alike() {
    let (w, h) = (64, 48);
    let finger = solid(w, h, [180, 110, 40]);
    let lit = solid(w, h, [210, 140, 70]);
    let chroma = Preprocess {
        size_px: 16,
        signal: Signal::Chroma,
        ..Preprocess::default()
    };
    let brightness = Preprocess {
        signal: Signal::Brightness,
        ..chroma
    };
    for p in [chroma, brightness] {
        let table = FingerTable::new(&p);
        let (a, b) = (
            table.apply(w, h, &finger).expect("valid"),
            table.apply(w, h, &lit).expect("valid"),
        );
        assert_eq!(a, p.apply(w, h, &finger).expect("valid"));
        let want = match p.signal {
            Signal::Chroma => 140.0 / 255.0,
            Signal::Brightness => 330.0 / 3.0 / 255.0,
        };
        assert!((a[0] - want).abs() < 1e-6, "{} {a:?}", p.signal);
        assert_eq!(a == b, p.signal == Signal::Chroma, "{}", p.signal);
    }
}

/// Artifacts from before the signal existed read as brightness, and a brightness
/// model writes no `signal` key (older builds read it back).
#[test]
fn the_signal_is_optional_in_stored_settings() {
    let old = r#"{"size_px":32,"channels":1,"hue_min_deg":10.0,"hue_max_deg":75.0,"saturation_min":0.35,"value_min":0.2}"#;
    let p: Preprocess = serde_json::from_str(old).expect("old settings");
    assert_eq!(p, Preprocess::default());
    assert_eq!(serde_json::to_string(&p).expect("json"), old);
    let chroma = Preprocess {
        signal: Signal::Chroma,
        ..p
    };
    let json = serde_json::to_string(&chroma).expect("json");
    assert!(json.ends_with(r#""signal":"chroma"}"#), "{json}");
    assert_eq!(serde_json::from_str::<Preprocess>(&json).ok(), Some(chroma));
    assert!(serde_json::from_str::<Preprocess>(&json.replace("chroma", "hue")).is_err());
}

/// The early-exit threshold and its table decide every one of the 2²⁴ colours
/// exactly as thresholding the full HSV conversion does, for the default window, a window
/// across 0° and zero thresholds (where greys pass).
#[test]
fn the_fast_threshold_equals_the_hsv_definition_on_every_colour() {
    let reference = |p: &Preprocess, r, g, b| {
        let (h, s, v) = hsv(r, g, b);
        v >= p.value_min && s >= p.saturation_min && p.hue_in_window(h)
    };
    let params = [
        Preprocess::default(),
        reds_and_greys(),
        // Every hue, saturation ≥ 0.55: (200, 100, b) keeps low and high blues but
        // not the middle ones, so the table falls back on its bits.
        Preprocess {
            hue_min_deg: 0.0,
            hue_max_deg: 359.9,
            saturation_min: 0.55,
            value_min: 0.0,
            ..Preprocess::default()
        },
    ];
    for (i, p) in params.iter().enumerate() {
        let table = FingerTable::new(p);
        assert_eq!(table.blue_runs.is_some(), i < 2, "{p:?}");
        // The rule's intervals are of hue and saturation, not of blue: it holds
        // where the blue runs do not.
        assert!(table.rule.is_some(), "{p:?}");
        // A rule for other parameters is refused.
        let other = rule::IntegerRule::derive(&params[(i + 1) % params.len()]).expect("rule");
        assert!(!FingerTable::agrees(&other, &table.bits), "{p:?}");
        let mut kept = 0u32;
        for r in 0..=255u8 {
            for g in 0..=255u8 {
                for b in 0..=255u8 {
                    let fast = p.is_finger(r, g, b);
                    assert_eq!(fast, reference(p, r, g, b), "({r}, {g}, {b}) with {p:?}");
                    assert_eq!(table.contains(r, g, b), fast, "table at ({r}, {g}, {b})");
                    kept += u32::from(fast);
                }
            }
        }
        assert!(kept > 0 && kept < 1 << 24, "{kept} kept with {p:?}");
    }
}

/// The vector rule (AVX-512 where this machine has it, AVX2 where it has that,
/// the compiler's vector code for three channels and for the row's tail) adds up
/// every colour exactly as the lookup does.
#[test]
fn the_vector_rule_sums_every_colour_as_the_lookup_does() {
    let params = [
        Preprocess::default(),
        reds_and_greys(),
        Preprocess {
            hue_min_deg: 200.0,
            hue_max_deg: 200.5,
            saturation_min: 1.0,
            value_min: 1.0,
            ..Preprocess::default()
        },
        Preprocess {
            signal: Signal::Chroma,
            ..Preprocess::default()
        },
    ];
    for p in &params {
        let table = FingerTable::new(p);
        let rule = table.rule.as_ref().expect("one interval per test");
        for r in 0..=255u8 {
            // Every (green, blue) after this red, less a few so that the row ends
            // part-way through a vector step.
            let row: Vec<u8> = (0..(1usize << 16) - 5)
                .flat_map(|gb| [r, (gb >> 8) as u8, gb as u8])
                .collect();
            let pixels = row.len() / 3;
            for grey in [true, false] {
                let per_pixel = if grey { 1 } else { 3 };
                let mut fast = vec![0u16; pixels * per_pixel];
                let mut looked_up = fast.clone();
                rule.add_row(&row, grey, &mut fast);
                add_row_per_pixel(&row, grey, p.signal, &mut looked_up, |r, g, b| {
                    table.contains(r, g, b)
                });
                let mut runs = vec![("the best path here", fast)];
                // The AVX2 row too, where this machine has it but takes AVX-512.
                let mut avx2 = vec![0u16; pixels];
                #[cfg(target_arch = "x86_64")]
                if grey && rule.add_grey_row_avx2(&row, &mut avx2) {
                    runs.push(("AVX2", avx2));
                }
                for (path, sums) in runs {
                    if let Some(i) = (0..sums.len()).find(|&i| sums[i] != looked_up[i]) {
                        let px = &row[i / per_pixel * 3..i / per_pixel * 3 + 3];
                        panic!(
                            "{path}: {px:?} (grey {grey}) sums {} against {} with {p:?}",
                            sums[i], looked_up[i]
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn a_hue_window_across_zero_keeps_reds() {
    let p = Preprocess {
        hue_min_deg: 340.0,
        hue_max_deg: 20.0,
        ..Preprocess::default()
    };
    assert!(p.is_finger(255, 0, 10));
    assert!(p.is_finger(255, 40, 0));
    assert!(!p.is_finger(0, 255, 0));
}
