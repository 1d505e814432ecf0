//! `softtouch config show|check`.

use super::{Failure, io_failure};
use clap::{Subcommand, ValueEnum};
use softtouch_collector::configs;
use softtouch_schemas::config::to_toml;
use softtouch_schemas::defaults;
use std::io::Write;
use std::path::PathBuf;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Which {
    /// The rig config.
    Rig,
    /// The scene spec.
    Scene,
}

#[derive(Debug, Subcommand)]
pub enum ConfigCommand {
    /// Print the resolved rig and/or scene as TOML you can copy and edit.
    ///
    /// Without files, prints the embedded defaults (an all-simulated rig and the
    /// paper's on-land scene) with their comments.
    #[command(
        after_help = "Examples:\n  softtouch config show rig > rig.toml\n  softtouch config show rig fr3 > rig.toml   # a Franka FR3 rig: set arm.address\n  softtouch config show scene > scene.toml\n  softtouch config show scene grasp-water > my-tank.toml   # a built-in scene to edit\n  softtouch config show --rig rig.toml --scene water.toml\n\nBuilt-in scenes (also usable as --scene NAME from any folder): land, water, grasp, grasp-water."
    )]
    Show {
        /// Show only this one.
        which: Option<Which>,
        /// With `scene`: the built-in scene of this name (land, water, grasp,
        /// grasp-water); with `rig`: the built-in rig (sim, the default; fr3, a
        /// Franka FR3 with a workspace it reaches); as shipped, comments included.
        name: Option<String>,
        /// Rig config file (default: embedded all-simulated rig).
        #[arg(long)]
        rig: Option<PathBuf>,
        /// Scene file (default: embedded on-land scene).
        #[arg(long)]
        scene: Option<PathBuf>,
    },
    /// Check a rig and a scene: every field, every range, and that the scene's poses
    /// lie inside the rig's workspace. `--rig` alone checks the rig alone (a grasp
    /// uses no scene; a collection checks its scene when it starts).
    #[command(
        after_help = "Examples:\n  softtouch config check --rig rig.toml --scene scenes/water.toml\n  softtouch config check --rig rig.toml      # the rig alone"
    )]
    Check {
        /// Rig config file (default: embedded all-simulated rig).
        #[arg(long)]
        rig: Option<PathBuf>,
        /// Scene file (default: embedded on-land scene).
        #[arg(long)]
        scene: Option<PathBuf>,
    },
}

pub fn run(cmd: ConfigCommand, out: &mut dyn Write) -> Result<(), Failure> {
    match cmd {
        ConfigCommand::Show {
            which,
            name: Some(name),
            ..
        } => {
            if which == Some(Which::Rig) {
                let (_, text) = defaults::builtin_rig(&name).ok_or_else(|| {
                    Failure::BadInput(anyhow::anyhow!(
                        "no built-in rig `{name}`: expected one of {}",
                        defaults::BUILTIN_RIGS
                            .iter()
                            .map(|(n, _)| *n)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                })?;
                return out.write_all(text.as_bytes()).map_err(io_failure);
            }
            if which != Some(Which::Scene) {
                return Err(Failure::BadInput(anyhow::anyhow!(
                    "`{name}`: say which: softtouch config show scene {name}, or config show rig {name}"
                )));
            }
            let (_, text) = defaults::builtin_scene(&name).ok_or_else(|| {
                Failure::BadInput(anyhow::anyhow!(
                    "no built-in scene `{name}`: expected one of {}",
                    defaults::builtin_scene_names()
                ))
            })?;
            out.write_all(text.as_bytes()).map_err(io_failure)
        }
        ConfigCommand::Show {
            which, rig, scene, ..
        } => {
            let resolved = configs::resolve(rig.as_deref(), scene.as_deref())?;
            // The embedded defaults are printed as written, comments included.
            let rig_text = if rig.is_some() {
                to_toml(&resolved.rig)
            } else {
                defaults::RIG_TOML.to_owned()
            };
            let scene_text = if scene.is_some() {
                to_toml(&resolved.scene)
            } else {
                defaults::SCENE_TOML.to_owned()
            };
            let text = match which {
                Some(Which::Rig) => rig_text,
                Some(Which::Scene) => scene_text,
                None => format!(
                    "# ===== rig ({}) =====\n{rig_text}\n# ===== scene ({}) =====\n{scene_text}",
                    resolved.rig_source, resolved.scene_source
                ),
            };
            out.write_all(text.as_bytes()).map_err(io_failure)
        }
        ConfigCommand::Check {
            rig: Some(rig),
            scene: None,
        } => {
            let (rig_config, source) = configs::rig(Some(&rig))?;
            if let Some(reach) = franka_reach(&rig_config)
                .map_err(|e| Failure::BadInput(anyhow::anyhow!("{source}: arm: {e}")))?
            {
                writeln!(out, "{reach}").map_err(io_failure)?;
            }
            writeln!(
                out,
                "ok: rig {source} (alone: give --scene to check a collection's poses against its workspace)"
            )
            .map_err(io_failure)
        }
        ConfigCommand::Check { rig, scene } => {
            let resolved = configs::resolve(rig.as_deref(), scene.as_deref())?;
            // The objects as the simulated grasp takes them (a floating one refused).
            softtouch_sim::check_scene_objects(&resolved.scene).map_err(|e| {
                Failure::BadInput(anyhow::anyhow!("{}: {e}", resolved.scene_source))
            })?;
            if let Some(reach) = franka_reach(&resolved.rig).map_err(|e| {
                Failure::BadInput(anyhow::anyhow!("{}: arm: {e}", resolved.rig_source))
            })? {
                writeln!(out, "{reach}").map_err(io_failure)?;
            }
            writeln!(
                out,
                "ok: rig {} and scene {} ({} rods, {} effects, medium {})",
                resolved.rig_source,
                resolved.scene_source,
                resolved.scene.rods.len(),
                resolved.scene.effects.len(),
                resolved.scene.medium
            )
            .map_err(io_failure)
        }
    }
}

/// What to change when the FR3 cannot reach the workspace: the fields and values of
/// the built-in FR3 rig, which pass.
const FR3_HINT: &str = "To reach it, set workspace.base_from_rod = { translation_m = [0.58, 0.0, 0.6], rotation_wxyz = [0.0, 0.9238795325112867, -0.3826834323650898, 0.0] } (the rod's axis along the base's -z: the finger points down as at the FR3's home keyframe) and workspace.theta_rad = [-0.4, 0.4] (and the scene's poses.theta_rad within it); `softtouch config show rig fr3` prints a rig with both";

/// For a Franka arm: whether home and the workspace's corners lie within the FR3's
/// joint ranges and velocity limits, followed from its ready joints at the procedure's
/// speeds (`None` for a simulated arm). Offline, so Desk's end effector is taken as
/// none (the rig's `end_effector` alone); connect checks again from the arm's own
/// joints and end effector.
fn franka_reach(rig: &softtouch_schemas::RigConfig) -> Result<Option<String>, String> {
    use softtouch_drivers::franka::{FrankaConfig, MotionLimits, reach};
    let Some(config) = FrankaConfig::for_rig(rig) else {
        return Ok(None);
    };
    let kin = reach::Kinematics::new(config.ne_t_ee.unwrap_or(reach::IDENTITY));
    let Some(home) = config.route.first() else {
        return Ok(None);
    };
    let start = kin.solve(&home.pose, &reach::READY_Q).ok_or_else(|| {
        format!(
            "{}: the FR3 cannot reach it from its ready joints (flange at {:?} m in the base frame). {FR3_HINT}",
            home.name, home.pose.translation_m
        )
    })?;
    reach::check_route(
        &kin,
        reach::Robot::Fr3,
        &start,
        &config.route,
        config.motion_margin.map_or(config.limits, |m| MotionLimits::for_robot(reach::Robot::Fr3, m)).rot_speed_rad_s,
    )
    .map_err(|e| format!("{e} (checked against the FR3 from its ready joints; connect checks again from the arm's own). {FR3_HINT}"))?;
    Ok(Some(format!(
        "ok: arm: home and the workspace's {} corners within the FR3's joint ranges and velocity limits (from its ready joints; checked again at connect)",
        config.route.len() / 2
    )))
}
