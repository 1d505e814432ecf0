//! Render a few frames of the simulated finger (air and water, two contacts each)
//! to `docs/frames/`, and print the label ranges over 10 000 random default poses.
//!
//! `cargo run -p softtouch-drivers --example render_frames --release`

use rand::{RngExt, SeedableRng};
use softtouch_schemas::{ContactPose, SceneSpec, config};
use softtouch_sim::{SceneSim, encode_png};
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let out = root.join("docs/frames");
    std::fs::create_dir_all(&out)?;
    let air = softtouch_schemas::defaults::scene();
    let water: SceneSpec = config::load_toml(&root.join("scenes/water.toml"))?;
    let contacts = [
        (
            "a",
            "circle-10",
            ContactPose {
                x_m: 0.045,
                z_m: 0.02,
                theta_rad: 0.4,
            },
        ),
        (
            "b",
            "square-10",
            ContactPose {
                x_m: 0.03,
                z_m: -0.03,
                theta_rad: -2.0,
            },
        ),
    ];
    for (medium, scene) in [("air", &air), ("water", &water)] {
        let sim = SceneSim::new(scene, 7)?;
        let rest = sim.render(
            "circle-10",
            &ContactPose {
                x_m: -0.03,
                z_m: 0.0,
                theta_rad: 0.0,
            },
            0,
            0.0,
        )?;
        std::fs::write(
            out.join(format!("{medium}-rest.png")),
            encode_png(&rest.image)?,
        )?;
        for (i, (tag, rod, pose)) in contacts.iter().enumerate() {
            let r = sim.render(rod, pose, 1 + i as u64, 0.1 * (1 + i) as f64)?;
            let name = format!("{medium}-{tag}.png");
            std::fs::write(out.join(&name), encode_png(&r.image)?)?;
            let rest_nodes = sim.lattice_nodes(
                rod,
                &ContactPose {
                    x_m: -0.03,
                    ..*pose
                },
            )?;
            let nodes = sim.lattice_nodes(rod, pose)?;
            let max_disp = rest_nodes
                .iter()
                .zip(&nodes)
                .map(|(a, b)| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt())
                .fold(0.0, f64::max);
            println!(
                "{name}: {rod} {pose:?} -> {}; largest node displacement {:.2} mm",
                r.wrench_in_sensor,
                max_disp * 1e3
            );
        }
    }

    // Label ranges over 10k random default poses, rods in turn.
    let sim = SceneSim::new(&air, 0)?;
    let mut g = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let p = &air.poses;
    let mut lo = [f64::INFINITY; 6];
    let mut hi = [f64::NEG_INFINITY; 6];
    let mut sq = [0.0; 6];
    let n = 10_000;
    for i in 0..n {
        let pose = ContactPose {
            x_m: g.random_range(p.x_m.min..=p.x_m.max),
            z_m: g.random_range(p.z_m.min..=p.z_m.max),
            theta_rad: g.random_range(p.theta_rad.min..=p.theta_rad.max),
        };
        let rod = &air.rods[i % air.rods.len()].name;
        let w = sim.wrench(rod, &pose)?;
        let mut v = w.to_array();
        for t in &mut v[3..] {
            *t *= 1000.0;
        }
        for k in 0..6 {
            lo[k] = lo[k].min(v[k]);
            hi[k] = hi[k].max(v[k]);
            sq[k] += v[k] * v[k];
        }
    }
    println!("label ranges over {n} random default poses (forces N, torques N·mm):");
    for (k, axis) in softtouch_schemas::wrench::AXES.iter().enumerate() {
        println!(
            "  {}: min {:+9.3}  max {:+9.3}  rms {:8.3}",
            axis.key,
            lo[k],
            hi[k],
            (sq[k] / n as f64).sqrt()
        );
    }
    Ok(())
}
