//! `transfer --tare`: the image tare fitted from both datasets' rest frames, the water
//! test split loaded through it, and its paired latents.

use super::TransferArgs;
use crate::{Failure, io_failure};
use anyhow::anyhow;
use softtouch_lab::transfer::{Pairs, TestSplit, fit_tare, paired_test, test_split};
use softtouch_trainer::similarity::{Distribution, cosine_similarities, linear_cka};
use softtouch_trainer::{FingerTable, ModelArtifact, latent_means};
use std::io::Write;

/// Fits the tare (printed, and its numbers in `csv`), then the water test split
/// through it and its pairs.
pub(super) async fn fit_and_load(
    store: &softtouch_store::Store,
    args: &TransferArgs,
    land: &TestSplit,
    table: &FingerTable,
    preprocess: &softtouch_trainer::Preprocess,
    out: &mut dyn Write,
    csv: &mut String,
) -> Result<(TestSplit, Pairs), Failure> {
    let mut fit = fit_tare(store, &args.land, &args.water, preprocess).await?;
    if args.no_gain_map {
        fit.tare.gain_map = None;
    }
    writeln!(
        out,
        "image tare of `{}` against `{}` ({} water and {} land rest frames): {}; RMS difference of the rest frames on the finger {:.1} → {:.1} without a gain map, {:.1} with it (0–255)",
        args.water,
        args.land,
        fit.water_frames,
        fit.land_frames,
        fit.tare.describe(),
        fit.rms_before,
        fit.rms_after,
        fit.rms_after_map
    )
    .map_err(io_failure)?;
    let t = &fit.tare;
    for (metric, value) in [
        ("scale", t.scale),
        ("gain_r", t.gain[0]),
        ("gain_g", t.gain[1]),
        ("gain_b", t.gain[2]),
        ("offset_r", t.offset[0]),
        ("offset_g", t.offset[1]),
        ("offset_b", t.offset[2]),
        ("rms_before", fit.rms_before),
        ("rms_after", fit.rms_after),
        ("rms_after_map", fit.rms_after_map),
        ("gain_map", f64::from(u8::from(t.gain_map.is_some()))),
    ] {
        csv.push_str(&format!("tare,,water,,{metric},{value}\n"));
    }
    let split = test_split(store, &args.water, table, Some(t)).await?;
    tracing::debug!("the tare: {t:?}");
    let pairs = paired_test(store, land, &split, table).await?;
    Ok((split, pairs))
}

/// The paired latents through the tare: printed, in `csv`, and (cosine mean, CKA).
pub(super) fn latents(
    artifact: &ModelArtifact,
    pairs: &Pairs,
    model: &str,
    device: &burn::prelude::Device,
    out: &mut dyn Write,
    csv: &mut String,
) -> Result<(f64, f64), Failure> {
    let h = &artifact.header;
    let bad = |e: softtouch_trainer::similarity::SimilarityError| {
        Failure::BadInput(anyhow!("paired latents with the tare: {e}"))
    };
    let lw = latent_means(&artifact.net, &h.config, &h.norm, &pairs.land, device);
    let ww = latent_means(&artifact.net, &h.config, &h.norm, &pairs.water, device);
    let c = Distribution::of(&cosine_similarities(&lw, &ww).map_err(bad)?).map_err(bad)?;
    let k = linear_cka(&lw, &ww).map_err(bad)?;
    writeln!(
        out,
        "  with the image tare: cosine mean {:.4}, median {:.4}; linear CKA {k:.4}",
        c.mean, c.median
    )
    .map_err(io_failure)?;
    for (metric, value) in [
        ("cosine_mean", c.mean),
        ("cosine_median", c.median),
        ("cka", k),
    ] {
        csv.push_str(&format!("latents,{model},paired_tare,,{metric},{value}\n"));
    }
    Ok((c.mean, k))
}
