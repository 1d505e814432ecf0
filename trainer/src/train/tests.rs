use super::*;
use crate::model::ModelKind;
use crate::preprocess::Preprocess;

/// Nets built from one seed in concurrent threads get the same weights: burn's
/// generator is process-wide and parameters draw lazily, so without the lock and
/// the materialisation under it one thread's draws land in another's net.
#[test]
fn the_same_seed_gives_the_same_weights_under_concurrency() {
    let config = ModelConfig {
        kind: ModelKind::Svae,
        width: 4,
        latent: 6,
        preprocess: Preprocess {
            size_px: 16,
            ..Preprocess::default()
        },
        ..ModelConfig::default()
    };
    let device = Device::flex();
    let weights: Vec<Vec<f32>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..4)
            .map(|i| {
                let device = device.clone();
                s.spawn(move || {
                    let mut last = Vec::new();
                    for _ in 0..100 {
                        // Every other thread builds another seed's net in between.
                        let seed = if i % 2 == 0 { 7 } else { 8 };
                        let net = init_net(&config, seed, &device);
                        let mut values = Values(Vec::new());
                        net.visit(&mut values);
                        last = values.0;
                    }
                    last
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("thread"))
            .collect()
    });
    // Bit-exact, compared without printing thousands of values.
    let same = |a: &[f32], b: &[f32]| {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
    };
    assert!(same(&weights[0], &weights[2]), "seed 7 gave two nets");
    assert!(same(&weights[1], &weights[3]), "seed 8 gave two nets");
    assert!(
        !same(&weights[0], &weights[1]),
        "seeds 7 and 8 gave one net"
    );
}

/// Every float parameter's values, in module order.
struct Values(Vec<f32>);

impl burn::module::ModuleVisitor for Values {
    fn visit_float<const D: usize>(&mut self, param: &burn::module::Param<Tensor<D>>) {
        let data = param.val().into_data();
        self.0
            .extend_from_slice(data.as_slice::<f32>().expect("f32 parameters"));
    }
}
