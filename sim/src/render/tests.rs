use super::*;

fn line(y_a: f32, y_b: f32) -> Line {
    ((100.0, y_a), (400.0, y_b), 3.0, [255.0, 140.0, 36.0])
}

#[test]
fn the_split_halves_the_beams_pixels() {
    // Nothing to draw: the middle.
    assert_eq!(split_row(&[], 0.0, 0.5), H / 2);
    // Two equal beams: between them.
    let s = split_row(&[line(100.0, 100.0), line(380.0, 380.0)], 0.0, 0.5);
    assert!((100..=380).contains(&s), "split at {s}");
    // All the work near the top: the split follows it.
    let top = [line(10.0, 10.0), line(20.0, 20.0), line(30.0, 30.0)];
    let s = split_row(&top, 0.0, 0.5);
    assert!((10..=30).contains(&s), "split at {s}");
    // One long beam down the whole frame: about the middle.
    let s = split_row(&[((320.0, -50.0), (320.0, 530.0), 3.0, [0.0; 3])], 0.0, 0.5);
    assert!(s.abs_diff(H / 2) <= 2, "split at {s}");
}

#[test]
fn the_split_counts_the_rows_copies_and_effects() {
    // Rows alone: the middle.
    assert_eq!(split_row(&[], 53.0, 0.5), H / 2);
    // Beams near the top pull the split up, less the more a row costs: three
    // beams of about 2 460 px near the top and 480 rows of 53 put half the work
    // in the first ~170 rows.
    let top = [line(10.0, 10.0), line(20.0, 20.0), line(30.0, 30.0)];
    let beams_only = split_row(&top, 0.0, 0.5);
    let cheap_rows = split_row(&top, 1.0, 0.5);
    let dear_rows = split_row(&top, 53.0, 0.5);
    assert!(
        beams_only < cheap_rows && cheap_rows < dear_rows && dear_rows < H / 2,
        "splits {beams_only}, {cheap_rows}, {dear_rows}"
    );
    assert!((150..=190).contains(&dear_rows), "split at {dear_rows}");
    // A cost that is not a number or not positive counts as none.
    for bad in [f32::NAN, f32::INFINITY, -5.0, 0.0] {
        assert_eq!(split_row(&top, bad, 0.5), beams_only, "row cost {bad}");
    }
}

#[test]
fn the_split_gives_the_top_band_its_share() {
    // Rows alone: the share of the rows.
    for (share, row) in [(0.5, H / 2), (0.25, H / 4), (0.75, 3 * H / 4)] {
        assert_eq!(split_row(&[], 53.0, share), row, "share {share}");
    }
    // A smaller share moves the split up, never out of the frame.
    let beams = [line(100.0, 100.0), line(200.0, 200.0), line(380.0, 380.0)];
    let splits: Vec<usize> = [0.0, 0.2, 0.5, 0.8, 1.0]
        .iter()
        .map(|&share| split_row(&beams, 13.0, share))
        .collect();
    assert!(splits.is_sorted(), "splits {splits:?}");
    assert!(splits[1] < splits[2] && splits[2] < splits[3], "{splits:?}");
    assert!(splits.iter().all(|s| (1..H).contains(s)), "{splits:?}");
    // A share that is not a number is a half; one outside [0, 1] is clamped.
    assert_eq!(split_row(&beams, 13.0, f32::NAN), splits[2]);
    assert_eq!(split_row(&beams, 13.0, -3.0), splits[0]);
    assert_eq!(split_row(&beams, 13.0, 7.0), splits[4]);
}

#[test]
fn the_bands_shares_follow_their_times() {
    // Equal times: the share stays.
    assert_eq!(next_share(0.5, 1e-3, 1e-3).to_bits(), 0.5f32.to_bits());
    assert!((next_share(0.4, 1e-3, 1e-3) - 0.4).abs() < 1e-6);
    // Times in proportion to the shares: the bands cost the same per unit of
    // work, and the split goes halfway back to a half.
    assert!((next_share(0.4, 0.4e-3, 0.6e-3) - 0.45).abs() < 1e-6);
    // The top band slower: it gets less, halfway to where the times would match
    // (a top band 1.5× as dear per unit of work balances at 0.4).
    let s = next_share(0.5, 1.5e-3, 1e-3);
    assert!((s - 0.45).abs() < 1e-6, "share {s}");
    // Repeated, it settles where the times match.
    let mut s = 0.5f32;
    for _ in 0..40 {
        let (top, bottom) = (1.5 * f64::from(s), f64::from(1.0 - s));
        s = next_share(s, top, bottom);
    }
    assert!((s - 0.4).abs() < 1e-4, "share {s}");
    // Never past the reach, however lopsided the times.
    let (mut up, mut down) = (0.5f32, 0.5f32);
    for _ in 0..10 {
        up = next_share(up, 1e-9, 1.0);
        down = next_share(down, 1.0, 1e-9);
    }
    assert_eq!(down.to_bits(), (0.5 - BandBalance::REACH).to_bits());
    assert_eq!(up.to_bits(), (0.5 + BandBalance::REACH).to_bits());
    // Times that teach nothing leave the share as it was (within reach).
    for (top, bottom) in [
        (0.0, 1e-3),
        (1e-3, 0.0),
        (f64::NAN, 1e-3),
        (1e-3, f64::INFINITY),
        (-1e-3, 1e-3),
    ] {
        assert_eq!(
            next_share(0.45, top, bottom).to_bits(),
            0.45f32.to_bits(),
            "{top} {bottom}"
        );
    }
    assert_eq!(next_share(f32::NAN, 1e-3, 1e-3).to_bits(), 0.5f32.to_bits());
    assert_eq!(
        next_share(0.99, 0.0, 0.0).to_bits(),
        (0.5 + BandBalance::REACH).to_bits()
    );
    // What a renderer learns starts at a half and is what it then uses.
    let balance = BandBalance::default();
    assert_eq!(balance.top_share().to_bits(), 0.5f32.to_bits());
    balance.learn(0.5, 1.5e-3, 1e-3);
    assert!((balance.top_share() - 0.45).abs() < 1e-6);
}

#[test]
fn the_split_stays_inside_the_frame_on_extreme_beams() {
    let far = 1e30_f32;
    for lines in [
        vec![((0.0, f32::NAN), (10.0, f32::NAN), 3.0, [0.0; 3])],
        vec![((0.0, -far), (10.0, -far), 3.0, [0.0; 3])],
        vec![((0.0, far), (10.0, far), 3.0, [0.0; 3])],
        vec![((-far, -far), (far, far), 3.0, [0.0; 3])],
        vec![((f32::INFINITY, 0.0), (0.0, 479.0), 3.0, [0.0; 3])],
        vec![((5.0, 0.0), (5.0, 0.0), 0.5, [0.0; 3])],
        vec![((5.0, 479.9), (600.0, 479.9), 3.0, [0.0; 3])],
    ] {
        for row_cost in [0.0, 53.0] {
            let s = split_row(&lines, row_cost, 0.5);
            assert!((1..H).contains(&s), "split at {s} for {lines:?}");
        }
    }
}

#[test]
fn a_line_drawn_in_bands_is_the_line_drawn_whole() {
    // Steep, shallow, flat, reversed, past the frame's edges, a dot: every split
    // row gives the bytes of one pass.
    let lines: [Line; 7] = [
        ((10.0, 5.0), (600.0, 470.0), 3.0, [250.0, 140.0, 30.0]),
        ((620.0, 30.0), (15.0, 90.0), 2.2, [200.0, 120.0, 20.0]),
        ((100.0, 240.5), (500.0, 240.5), 3.0, [255.0, 255.0, 255.0]),
        ((300.0, -40.0), (310.0, 520.0), 1.5, [90.0, 200.0, 10.0]),
        ((-80.0, 200.0), (700.0, 260.0), 0.5, [255.0, 0.0, 0.0]),
        ((320.0, 239.0), (320.2, 239.1), 3.0, [0.0, 255.0, 0.0]),
        ((50.0, 470.0), (630.0, 478.0), 3.0, [10.0, 20.0, 255.0]),
    ];
    let mut whole = vec![40u8; W * H * 3];
    for &(p0, p1, hw, c) in &lines {
        draw_line(&mut whole, (0, H as i32), p0, p1, hw, c);
    }
    for split in [1, 7, 100, 239, 240, 241, 400, 479] {
        let mut banded = vec![40u8; W * H * 3];
        let (top, bottom) = banded.split_at_mut(split * W * 3);
        for &(p0, p1, hw, c) in &lines {
            draw_line(top, (0, split as i32), p0, p1, hw, c);
            draw_line(bottom, (split as i32, H as i32), p0, p1, hw, c);
        }
        assert!(banded == whole, "split at row {split}");
    }
}

/// FNV-1a over a frame's bytes: pins a drawing to the bytes it had.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

#[test]
fn lines_draw_the_bytes_they_always_drew() {
    // Beams of every width and direction, ends inside and past the frame, and a
    // dot, over each other.
    let mut frame = vec![40u8; W * H * 3];
    for k in 0..60 {
        let t = k as f32;
        let p0 = ((t * 37.0) % 700.0 - 30.0, (t * 53.0) % 540.0 - 30.0);
        let p1 = (
            p0.0 + ((k * 41) % 181) as f32 - 90.0,
            p0.1 + ((k * 29) % 141) as f32 - 70.0,
        );
        let half_w = 0.5 + (k % 6) as f32 * 0.5;
        let c = [255.0 - t * 3.0, 140.0, 36.0 + t * 2.0];
        draw_line(&mut frame, (0, H as i32), p0, p1, half_w, c);
    }
    draw_line(
        &mut frame,
        (0, H as i32),
        (320.0, 239.0),
        (320.2, 239.1),
        3.0,
        [0.0, 255.0, 0.0],
    );
    // The digest of these bytes as drawn before the caps' pixels were worked out
    // in lanes (and since): any change to how a beam is drawn shows here.
    assert_eq!(fnv1a(&frame), 0xd9b0_49db_b8a5_3163);
}

#[test]
fn pixels_in_lanes_blend_as_one_at_a_time() {
    // Columns shorter and longer than a block of lanes, along a row and down a
    // column, with coverages from none to full.
    let coverage = |ib: i32| [0, 1, 128, 255, 256, 7, 0, 200][(ib.rem_euclid(8)) as usize];
    for (step, len) in [(3, 40 * 3), (W * 3, 40 * W * 3)] {
        for (blo, bhi) in [(0, 0), (3, 17), (0, 15), (0, 16), (5, 39), (2, 33)] {
            let mut lanes: Vec<u8> = (0..len).map(|i| (i * 7 % 251) as u8).collect();
            let mut one_by_one = lanes.clone();
            let first = blo as usize * step;
            let solid = [250, 3, 128];
            blend_lanes(&mut lanes, first, step, (blo, bhi), solid, coverage);
            for ib in blo..=bhi {
                let o = ib as usize * step;
                blend_256(&mut one_by_one[o..o + 3], solid, coverage(ib));
            }
            assert!(lanes == one_by_one, "step {step}, pixels {blo}..={bhi}");
        }
    }
    // A full coverage gives the colour, none leaves the pixel.
    let mut px = [10u8, 200, 99];
    blend_256(&mut px, [250, 3, 128], 256);
    assert_eq!(px, [250, 3, 128]);
    blend_256(&mut px, [0, 0, 0], 0);
    assert_eq!(px, [250, 3, 128]);
}

#[test]
fn camera_noise_is_the_same_in_one_byte_or_two() {
    assert!(matches!(
        NoiseTable::new(vec![-128, 0, 127]),
        NoiseTable::Narrow(_)
    ));
    assert!(matches!(
        NoiseTable::new(vec![-129, 0]),
        NoiseTable::Wide(_)
    ));
    assert!(matches!(NoiseTable::new(vec![0, 128]), NoiseTable::Wide(_)));
    let levels: Vec<i16> = vec![-128, -5, 0, 3, 127, -1, 100, -100];
    let narrow = NoiseTable::new(levels.clone());
    let wide = NoiseTable::Wide(levels);
    // Saturation at both ends, from two offsets.
    let frame = [0u8, 2, 255, 254, 130, 0, 200, 50];
    for at in [0, 2] {
        let (mut a, mut b) = (frame[..6].to_vec(), frame[..6].to_vec());
        narrow.add_to(&mut a, at);
        wide.add_to(&mut b, at);
        assert_eq!(a, b, "offset {at}");
    }
    let mut a = frame.to_vec();
    narrow.add_to(&mut a, 0);
    assert_eq!(a, [0, 0, 255, 255, 255, 0, 255, 0]);
}
