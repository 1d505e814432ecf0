use super::*;

const W: usize = 160;
const H: usize = 120;

/// A rest frame with structure at several scales: an orange blob (the finger), a
/// gradient and rings.
fn land() -> RestFrame {
    let mut rgb = vec![0u8; W * H * 3];
    for y in 0..H {
        for x in 0..W {
            let (dx, dy) = (x as f64 - 70.0, y as f64 - 66.0);
            let r = (dx * dx + dy * dy).sqrt();
            let ring = 20.0 * (r / 6.0).sin();
            let px = if r < 35.0 {
                [230.0 + ring * 0.5, 130.0 + ring, 40.0]
            } else {
                [40.0 + y as f64 * 0.3, 60.0 + ring, 90.0 + x as f64 * 0.2]
            };
            for c in 0..3 {
                rgb[(y * W + x) * 3 + c] = px[c].round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    RestFrame {
        width: W,
        height: H,
        rgb,
    }
}

/// `f` as water would show it: magnified `m` about the centre, then each channel
/// times `g` plus `o`.
fn through_water(f: &RestFrame, m: f64, g: [f64; 3], o: [f64; 3]) -> RestFrame {
    let t = ImageTare {
        scale: 1.0 / m,
        gain: g,
        offset: o,
        ..ImageTare::identity(f.width, f.height)
    };
    RestFrame {
        rgb: t.apply(f.width, f.height, &f.rgb).expect("apply"),
        ..f.clone()
    }
}

#[test]
fn the_fit_undoes_a_flat_ports_magnification_and_the_waters_colour() {
    let l = land();
    let (g, o) = ([0.7, 0.75, 0.9], [4.0, 8.0, 20.0]);
    let w = through_water(&l, 1.333, g, o);
    let fit = fit_image_tare(
        std::slice::from_ref(&l),
        &[w.clone(), w],
        None,
        TareGains::PerChannel,
    )
    .expect("fit");
    let t = &fit.tare;
    assert!((t.scale - 1.333).abs() < 0.01, "{t:?}");
    for c in 0..3 {
        assert!((t.gain[c] - 1.0 / g[c]).abs() < 0.06, "{t:?}");
        assert!((t.offset[c] + o[c] / g[c]).abs() < 6.0, "{t:?}");
    }
    assert!(
        fit.rms_after < 0.3 * fit.rms_before,
        "{} → {}",
        fit.rms_before,
        fit.rms_after
    );
    assert_eq!((fit.land_frames, fit.water_frames), (1, 2));
    assert!(t.describe().starts_with("scale 1.33"), "{}", t.describe());
}

#[test]
fn the_same_medium_fits_the_identity() {
    let l = land();
    let fit = fit_image_tare(
        std::slice::from_ref(&l),
        std::slice::from_ref(&l),
        None,
        TareGains::PerChannel,
    )
    .expect("fit");
    let t = &fit.tare;
    assert!((t.scale - 1.0).abs() < 0.005, "{t:?}");
    for c in 0..3 {
        assert!(
            (t.gain[c] - 1.0).abs() < 0.02 && t.offset[c].abs() < 3.0,
            "{t:?}"
        );
    }
    assert!(fit.rms_before < 1e-6 && fit.rms_after < 1e-3, "{fit:?}");
}

#[test]
fn the_identity_changes_no_pixel() {
    let l = land();
    let out = ImageTare::identity(W, H)
        .apply(W, H, &l.rgb)
        .expect("apply");
    assert_eq!(out, l.rgb);
}

#[test]
fn a_magnified_frame_corrected_matches_land_inside_the_field_it_still_sees() {
    let l = land();
    let w = through_water(&l, 1.25, [1.0; 3], [0.0; 3]);
    let t = ImageTare {
        scale: 1.25,
        ..ImageTare::identity(W, H)
    };
    let back = t.apply(W, H, &w.rgb).expect("apply");
    // The centre (the water frame saw it whole): within a few units of land on
    // average (two bilinear resamplings soften the blob's hard edge).
    let (mut sum, mut n) = (0i64, 0i64);
    for y in H / 2 - 20..H / 2 + 20 {
        for x in W / 2 - 30..W / 2 + 30 {
            for c in 0..3 {
                let i = (y * W + x) * 3 + c;
                sum += i64::from((i32::from(back[i]) - i32::from(l.rgb[i])).abs());
                n += 1;
            }
        }
    }
    assert!(
        sum as f64 / (n as f64) < 3.0,
        "mean difference {}",
        sum as f64 / n as f64
    );
    // The corners lie outside what water saw: black.
    assert_eq!(&back[0..3], &[0, 0, 0]);
}

#[test]
fn bad_inputs_are_named_not_panicked_on() {
    let l = land();
    assert_eq!(
        fit_image_tare(&[], std::slice::from_ref(&l), None, TareGains::PerChannel),
        Err(TareError::NoFrames("land"))
    );
    assert_eq!(
        fit_image_tare(std::slice::from_ref(&l), &[], None, TareGains::PerChannel),
        Err(TareError::NoFrames("water"))
    );
    let small = RestFrame {
        width: 80,
        height: 60,
        rgb: vec![9; 80 * 60 * 3],
    };
    let e = fit_image_tare(
        std::slice::from_ref(&l),
        &[small],
        None,
        TareGains::PerChannel,
    )
    .expect_err("sizes");
    assert!(e.to_string().contains("water rest frame 1 is 80×60"), "{e}");
    let short = RestFrame {
        rgb: vec![0; 10],
        ..l.clone()
    };
    let e = fit_image_tare(
        std::slice::from_ref(&l),
        &[short],
        None,
        TareGains::PerChannel,
    )
    .expect_err("buffer");
    assert!(e.to_string().contains("10 bytes"), "{e}");
    // A capped camera: every pixel alike.
    let flat = RestFrame {
        rgb: vec![17; W * H * 3],
        ..l.clone()
    };
    assert_eq!(
        fit_image_tare(
            std::slice::from_ref(&l),
            std::slice::from_ref(&flat),
            None,
            TareGains::PerChannel
        ),
        Err(TareError::Flat("water"))
    );
    assert_eq!(
        fit_image_tare(
            std::slice::from_ref(&flat),
            std::slice::from_ref(&l),
            None,
            TareGains::PerChannel
        ),
        Err(TareError::Flat("land"))
    );
    // A one-pixel frame: flat, named.
    let one = RestFrame {
        width: 1,
        height: 1,
        rgb: vec![1, 2, 3],
    };
    assert!(
        fit_image_tare(
            std::slice::from_ref(&one),
            std::slice::from_ref(&one),
            None,
            TareGains::PerChannel
        )
        .is_err()
    );
    // A tare with a NaN or a zero scale is refused, and a wrong buffer.
    let mut t = ImageTare::identity(W, H);
    t.gain[1] = f64::NAN;
    assert!(matches!(t.apply(W, H, &l.rgb), Err(TareError::Invalid(_))));
    t = ImageTare {
        scale: 0.0,
        ..ImageTare::identity(W, H)
    };
    assert!(matches!(t.apply(W, H, &l.rgb), Err(TareError::Invalid(_))));
    assert!(matches!(
        ImageTare::identity(W, H).apply(W, H, &l.rgb[..9]),
        Err(TareError::Size(_))
    ));
    assert!(matches!(
        ImageTare::identity(0, 0).apply(0, 0, &[]),
        Err(TareError::Size(_))
    ));
}

#[test]
fn saturated_and_extreme_corrections_stay_in_range() {
    let l = land();
    let t = ImageTare {
        scale: 1e-6,
        gain: [1e6, -1e6, 0.0],
        offset: [0.0, 0.0, 1e9],
        ..ImageTare::identity(W, H)
    };
    let out = t.apply(W, H, &l.rgb).expect("apply");
    assert_eq!(out.len(), l.rgb.len());
    assert!(out.chunks_exact(3).all(|p| p[2] == 255));
}

/// For a chroma model: one gain for the three channels, one map value per pixel, so
/// white light added to a water frame is still white after the tare, and the
/// finger's chroma is the same with and without it (per channel gains would tint
/// it: the light's crest times the gains' spread, in chroma).
#[test]
fn a_white_tare_keeps_added_white_light_white() {
    let l = land();
    let (g, o) = ([0.7, 0.75, 0.9], [4.0, 8.0, 20.0]);
    let w = through_water(&l, 1.333, g, o);
    let white = fit_image_tare(
        std::slice::from_ref(&l),
        std::slice::from_ref(&w),
        None,
        TareGains::for_signal(crate::Signal::Chroma),
    )
    .expect("fit");
    let t = &white.tare;
    assert!((t.scale - 1.333).abs() < 0.01, "{t:?}");
    let bits = t.gain.map(f64::to_bits);
    assert!(bits[0] == bits[1] && bits[1] == bits[2], "{t:?}");
    let map = t.gain_map.as_ref().expect("a map");
    assert!(
        map.gains
            .chunks_exact(3)
            .all(|p| p[0].to_bits() == p[1].to_bits() && p[1].to_bits() == p[2].to_bits()),
        "one map value per pixel"
    );
    // 20 units of white light over the water frame, read through each tare.
    let lit = RestFrame {
        rgb: w.rgb.iter().map(|&v| v.saturating_add(20)).collect(),
        ..w.clone()
    };
    let per_channel = fit_image_tare(
        std::slice::from_ref(&l),
        std::slice::from_ref(&w),
        None,
        TareGains::for_signal(crate::Signal::Brightness),
    )
    .expect("fit");
    let chroma_shift = |tare: &ImageTare| {
        let (a, b) = (
            tare.apply(W, H, &w.rgb).expect("apply"),
            tare.apply(W, H, &lit.rgb).expect("apply"),
        );
        let chroma = |p: &[u8]| {
            i32::from(*p.iter().max().unwrap_or(&0)) - i32::from(*p.iter().min().unwrap_or(&0))
        };
        // The finger's middle, away from the frame's edge and the clamp.
        let at = |f: &[u8], x: usize, y: usize| chroma(&f[(y * W + x) * 3..(y * W + x) * 3 + 3]);
        (55..85)
            .flat_map(|y| (55..85).map(move |x| (x, y)))
            .map(|(x, y)| (at(&b, x, y) - at(&a, x, y)).abs())
            .max()
            .unwrap_or(0)
    };
    assert!(
        chroma_shift(&white.tare) <= 1,
        "{}",
        chroma_shift(&white.tare)
    );
    assert!(
        chroma_shift(&per_channel.tare) >= 4,
        "{}",
        chroma_shift(&per_channel.tare)
    );
}
