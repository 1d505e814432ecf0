//! Running a trained net over examples: predictions, image error, latent means.

use super::*;

/// Runs a model (in evaluation mode) over `examples`: wrench predictions in label
/// units (if it predicts any) and the image MSE (if it reconstructs).
///
/// # Errors
/// The model returned other than one prediction per example.
pub fn evaluate(
    net: &Net,
    config: &ModelConfig,
    norm: &LabelNorm,
    examples: &[Example],
    device: &Device,
) -> Result<(Metrics, Option<Vec<WrenchLabel>>), TrainError> {
    let net = net.valid();
    let mut predictions = config.kind.predicts_wrench().then(Vec::new);
    let mut sq_err_sum = 0.0f64;
    let indices: Vec<usize> = (0..examples.len()).collect();
    for chunk in indices.chunks(64) {
        let (images, _) = batch_tensors(examples, chunk, config, norm, device);
        // Without a decoder there is nothing to reconstruct: the cheaper pass.
        let wrench = if config.kind.has_decoder() {
            let out = net.forward(images.clone(), None);
            if let Some(image) = out.image {
                let per_batch = mse(image, images).into_scalar::<f32>();
                sq_err_sum += f64::from(per_batch) * chunk.len() as f64;
            }
            out.wrench
        } else {
            net.forward_wrench(images).1
        };
        if let (Some(p), Some(w)) = (predictions.as_mut(), wrench) {
            p.extend(to_vec(w).chunks_exact(6).map(|z| norm.denormalise(z)));
        }
    }
    let targets: Vec<WrenchLabel> = examples.iter().map(|e| e.label).collect();
    let image_mse = config
        .kind
        .has_decoder()
        .then(|| sq_err_sum / examples.len().max(1) as f64);
    let metrics = Metrics::compute(predictions.as_deref(), &targets, image_mse)?;
    Ok((metrics, predictions))
}

/// The latent mean μ of every example (evaluation mode, batches of 64), one row per
/// example, as f64: the touch representation that the land-to-water comparison reads.
pub fn latent_means(
    net: &Net,
    config: &ModelConfig,
    norm: &LabelNorm,
    examples: &[Example],
    device: &Device,
) -> Vec<Vec<f64>> {
    let net = net.valid();
    let indices: Vec<usize> = (0..examples.len()).collect();
    let mut out = Vec::with_capacity(examples.len());
    for chunk in indices.chunks(64) {
        let (images, _) = batch_tensors(examples, chunk, config, norm, device);
        let (mean, _) = net.forward_wrench(images);
        let values = to_vec(mean);
        let per = values.len() / chunk.len().max(1);
        out.extend(
            values
                .chunks_exact(per.max(1))
                .map(|row| row.iter().map(|v| f64::from(*v)).collect()),
        );
    }
    out
}
