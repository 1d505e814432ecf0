//! `softtouch sim render`: one look at a scene.

use super::{Failure, io_failure};
use anyhow::anyhow;
use clap::Subcommand;
use softtouch_collector::configs;
use softtouch_schemas::ContactPose;
use std::io::Write;
use std::path::PathBuf;

#[derive(Debug, Subcommand)]
pub enum SimCommand {
    /// Render one frame of the simulated finger at a contact pose and print the true
    /// wrench: check a scene file before a night of collection.
    #[command(after_help = "Examples:
  softtouch sim render --pose 0.02,0.01,0.5 --out frame.png
  softtouch sim render --scene scenes/water.toml --rod oval-12 --pose=0.04,-0.03,-2.5 --out water.png

The pose is the contact pose x,z,θ in metres and radians (x ∈ [0, 0.05], z ∈ [−0.05, 0.05],
θ ∈ [−π, π] by default). Start it with `=` when x is negative: --pose=-0.01,0,0.")]
    Render {
        /// Scene (default: the embedded on-land scene).
        #[arg(long)]
        scene: Option<PathBuf>,
        /// Rod (default: the scene's first).
        #[arg(long)]
        rod: Option<String>,
        /// Contact pose `X,Z,THETA` (m, m, rad).
        #[arg(long, allow_hyphen_values = true)]
        pose: String,
        /// Write the frame here as PNG.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Seed of the scene's random effects.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
    /// Serve the simulated force/torque sensor over the Net F/T protocol (RDT on UDP,
    /// calibration on TCP one port below), so a lab can check its network setup and
    /// client against a sensor that answers like the real one. Runs until Ctrl-C.
    #[command(after_help = "Examples:
  softtouch sim netft                                  # 127.0.0.1:49152 (RDT), :49151 (calibration)
  softtouch sim netft --bind 0.0.0.0:49152 --pose 0.03,0.0,0.5 --rate-hz 7000

The finger is held pressed on the scene's first rod at --pose, so readings carry a
realistic wrench (and the scene's force/torque effects: noise, drift, packet loss …).
Counts per unit: 1 000 000 per N and per N·m, as the calibration request reports.")]
    Netft {
        /// UDP address for RDT; calibration listens on TCP one port below.
        #[arg(long, default_value = "127.0.0.1:49152")]
        bind: std::net::SocketAddr,
        /// Scene (default: the embedded on-land scene).
        #[arg(long)]
        scene: Option<PathBuf>,
        /// Contact pose `X,Z,THETA` the finger is held at (m, m, rad).
        #[arg(long, allow_hyphen_values = true, default_value = "0.03,0.0,0.5")]
        pose: String,
        /// Readings per second (up to 7000, as a Net F/T).
        #[arg(long, default_value_t = 1000.0)]
        rate_hz: f64,
        /// Seed of the scene's random effects.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
}

/// Parse `X,Z,THETA`.
pub fn parse_pose(text: &str) -> Result<ContactPose, String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let [x, z, theta] = parts.as_slice() else {
        return Err(format!(
            "--pose: expected X,Z,THETA (three numbers), found `{text}`"
        ));
    };
    let num = |name: &str, v: &str| -> Result<f64, String> {
        let n: f64 = v
            .parse()
            .map_err(|_| format!("--pose: {name} `{v}` is not a number"))?;
        if n.is_finite() {
            Ok(n)
        } else {
            Err(format!("--pose: {name} must be finite, found {v}"))
        }
    };
    Ok(ContactPose {
        x_m: num("X", x)?,
        z_m: num("Z", z)?,
        theta_rad: num("THETA", theta)?,
    })
}

pub async fn run(cmd: SimCommand, out: &mut dyn Write) -> Result<(), Failure> {
    match cmd {
        SimCommand::Netft {
            bind,
            scene,
            pose,
            rate_hz,
            seed,
        } => {
            use softtouch_drivers::Arm as _;
            let (scene, _) = configs::scene(scene.as_deref())?;
            let pose = parse_pose(&pose).map_err(|e| Failure::BadInput(anyhow!(e)))?;
            let mut rig = softtouch_schemas::defaults::rig();
            rig.force_sensor = softtouch_schemas::ForceSensorDevice::Sim { rate_hz };
            let mut check = softtouch_schemas::config::Check::default();
            softtouch_schemas::config::Validate::validate(&rig, &mut check);
            check.finish(&softtouch_schemas::ConfigSource::Stored("--rate-hz".into()))?;
            let clock = softtouch_drivers::TokioClock::new();
            let mut sim = softtouch_sim::SimRig::new(&rig, &scene, seed, clock)
                .map_err(|e| Failure::BadInput(e.into()))?;
            let target =
                softtouch_schemas::ArmPose::from_contact(&rig.workspace.base_from_rod, &pose);
            sim.arm.move_to(&target, 0.5).await.map_err(|e| {
                Failure::BadInput(anyhow!("cannot hold the finger at {pose:?}: {e}"))
            })?;
            let server = softtouch_drivers::netft::server::NetFtServer::bind(
                sim.force_sensor,
                softtouch_drivers::netft::server::ServerConfig::at(bind),
            )
            .await
            .map_err(|e| Failure::Runtime(e.into()))?;
            let rdt = server.rdt_addr().map_err(|e| Failure::Runtime(e.into()))?;
            let cal = server
                .calibration_addr()
                .map_err(|e| Failure::Runtime(e.into()))?;
            writeln!(
                out,
                "simulated Net F/T: RDT on udp://{rdt}, calibration on {}; {rate_hz} Hz; Ctrl-C stops",
                cal.map_or("(none)".into(), |a| format!("tcp://{a}"))
            )
            .map_err(io_failure)?;
            out.flush().map_err(io_failure)?;
            let stats = server
                .run(async {
                    let _ = tokio::signal::ctrl_c().await;
                })
                .await
                .map_err(|e| Failure::Runtime(e.into()))?;
            writeln!(out, "stopped: {stats:?}").map_err(io_failure)
        }
        SimCommand::Render {
            scene,
            rod,
            pose,
            out: png,
            seed,
        } => {
            let (scene, source) = configs::scene(scene.as_deref())?;
            let pose = parse_pose(&pose).map_err(|e| Failure::BadInput(anyhow!(e)))?;
            let rod = match rod {
                Some(r) => r,
                None => scene
                    .rods
                    .first()
                    .map(|r| r.name.clone())
                    .unwrap_or_default(),
            };
            let rendered = softtouch_sim::render_contact(&scene, &rod, &pose, seed)
                .map_err(|e| Failure::BadInput(anyhow!("{source}: {e}")))?;
            if let Some(path) = &png {
                let bytes = softtouch_sim::encode_png(&rendered.image)
                    .map_err(|e| Failure::Runtime(e.into()))?;
                std::fs::write(path, bytes).map_err(|e| {
                    Failure::Runtime(anyhow!("cannot write {}: {e}", path.display()))
                })?;
            }
            writeln!(
                out,
                "scene `{}` ({}), rod `{rod}`, pose x={} m z={} m θ={} rad\ntrue wrench in the sensor frame: {}{}",
                scene.name,
                scene.medium,
                pose.x_m,
                pose.z_m,
                pose.theta_rad,
                rendered.wrench_in_sensor,
                png.map(|p| format!("\nframe written to {}", p.display())).unwrap_or_default()
            )
            .map_err(io_failure)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poses_parse_or_say_what_is_wrong() {
        assert_eq!(
            parse_pose("0.01, -0.02,3").ok(),
            Some(ContactPose {
                x_m: 0.01,
                z_m: -0.02,
                theta_rad: 3.0
            })
        );
        let err = |s: &str| parse_pose(s).err().unwrap_or_default();
        assert!(err("0.01,0.02").contains("three numbers"));
        assert!(err("0.01,a,0").contains("Z `a` is not a number"));
        assert!(err("nan,0,0").contains("finite"));
        assert!(parse_pose("").is_err());
    }
}
