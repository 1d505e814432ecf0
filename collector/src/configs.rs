//! Resolving the rig config and the scene spec: a file when given, else the embedded
//! default; each validated, and the scene validated against the rig.

use softtouch_schemas::config::{Check, ConfigError, load_toml, parse_toml};
use softtouch_schemas::{ConfigSource, RigConfig, SceneSpec, defaults};
use std::path::Path;

/// A rig and a scene that passed every check, with where each came from.
#[derive(Debug, Clone)]
pub struct Resolved {
    /// The rig.
    pub rig: RigConfig,
    /// Where the rig came from.
    pub rig_source: ConfigSource,
    /// The scene.
    pub scene: SceneSpec,
    /// Where the scene came from.
    pub scene_source: ConfigSource,
}

/// Load the rig from `path`, or the embedded default.
pub fn rig(path: Option<&Path>) -> Result<(RigConfig, ConfigSource), ConfigError> {
    match path {
        Some(p) => Ok((load_toml(p)?, ConfigSource::File(p.to_owned()))),
        None => Ok((defaults::rig(), ConfigSource::Embedded("rig"))),
    }
}

/// Load the scene from `path`, or the embedded default. A `path` that is no file but
/// a built-in scene's name (`water`, `grasp-water`, …: [`defaults::BUILTIN_SCENES`])
/// is that scene, from any folder; a file of that name wins.
pub fn scene(path: Option<&Path>) -> Result<(SceneSpec, ConfigSource), ConfigError> {
    let Some(p) = path else {
        return Ok((defaults::scene(), ConfigSource::Embedded("scene")));
    };
    if !p.exists()
        && let Some((name, text)) = p.to_str().and_then(defaults::builtin_scene)
    {
        let source = ConfigSource::Embedded(name);
        return Ok((parse_toml(text, &source)?, source));
    }
    let scene = load_toml::<SceneSpec>(p).map_err(|mut e| {
        if !p.exists() {
            for problem in &mut e.problems {
                problem.message.push_str(&format!(
                    " (nor is it a built-in scene: {})",
                    defaults::builtin_scene_names()
                ));
            }
        }
        e
    })?;
    Ok((scene, ConfigSource::File(p.to_owned())))
}

/// Load both and check that the scene fits the rig.
pub fn resolve(
    rig_path: Option<&Path>,
    scene_path: Option<&Path>,
) -> Result<Resolved, ConfigError> {
    let (rig, rig_source) = rig(rig_path)?;
    let (scene, scene_source) = scene(scene_path)?;
    let mut check = Check::default();
    scene.validate_against(&rig, &mut check);
    check.finish(&scene_source)?;
    Ok(Resolved {
        rig,
        rig_source,
        scene,
        scene_source,
    })
}
