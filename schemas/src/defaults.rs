//! The embedded defaults: an all-simulated rig and the paper's on-land scene, so the
//! main job runs with no files at all.

use crate::config::{ConfigSource, parse_toml};
use crate::rig::RigConfig;
use crate::scene::SceneSpec;

/// The default rig, as TOML with comments (what `softtouch config show rig` prints).
pub const RIG_TOML: &str = include_str!("../defaults/rig.toml");
/// The default scene, as TOML with comments.
pub const SCENE_TOML: &str = include_str!("../defaults/scene.toml");
/// A Franka FR3 rig (`softtouch config show rig fr3`): the default with its arm real
/// and the franka-sim tier's workspace, which an FR3 reaches.
pub const RIG_FR3_TOML: &str = include_str!("../defaults/rig-fr3.toml");

/// The rigs built in, by name, as TOML with comments (`softtouch config show rig NAME`).
pub const BUILTIN_RIGS: [(&str, &str); 2] = [("sim", RIG_TOML), ("fr3", RIG_FR3_TOML)];

/// The built-in rig called `name`, as its name and TOML.
#[must_use]
pub fn builtin_rig(name: &str) -> Option<(&'static str, &'static str)> {
    BUILTIN_RIGS.iter().copied().find(|(n, _)| *n == name)
}

/// The scenes built in, by name, as TOML with comments: what `--scene NAME` reads
/// from any folder and `softtouch config show scene NAME` prints (`land` is the
/// default; the others are the checkout's `scenes/` files, embedded at build time).
pub const BUILTIN_SCENES: [(&str, &str); 4] = [
    ("land", SCENE_TOML),
    ("water", include_str!("../../scenes/water.toml")),
    ("grasp", GRASP_SCENE_TOML),
    ("grasp-water", GRASP_WATER_SCENE_TOML),
];
/// The grasp experiments' land scene (`scenes/grasp.toml`).
pub const GRASP_SCENE_TOML: &str = include_str!("../../scenes/grasp.toml");
/// The grasp experiments' water scene (`scenes/grasp-water.toml`).
pub const GRASP_WATER_SCENE_TOML: &str = include_str!("../../scenes/grasp-water.toml");

/// The built-in scene called `name`, as its name and TOML.
#[must_use]
pub fn builtin_scene(name: &str) -> Option<(&'static str, &'static str)> {
    BUILTIN_SCENES.iter().copied().find(|(n, _)| *n == name)
}

/// The built-in scenes' names, comma-separated.
#[must_use]
pub fn builtin_scene_names() -> String {
    BUILTIN_SCENES
        .iter()
        .map(|(n, _)| *n)
        .collect::<Vec<_>>()
        .join(", ")
}

/// The all-simulated rig.
#[must_use]
pub fn rig() -> RigConfig {
    // The embedded text is checked by this crate's tests; failing here is a build bug.
    #[allow(clippy::expect_used)]
    parse_toml(RIG_TOML, &ConfigSource::Embedded("rig")).expect("embedded default rig is valid")
}

/// The on-land scene with the paper's pose ranges and five rod shapes.
#[must_use]
pub fn scene() -> SceneSpec {
    #[allow(clippy::expect_used)]
    parse_toml(SCENE_TOML, &ConfigSource::Embedded("scene"))
        .expect("embedded default scene is valid")
}

#[cfg(test)]
mod builtin_tests {
    use super::*;

    #[test]
    fn every_built_in_scene_parses_and_checks() {
        for (name, text) in BUILTIN_SCENES {
            let scene: Result<SceneSpec, _> = parse_toml(text, &ConfigSource::Embedded(name));
            assert!(scene.is_ok(), "{name}: {scene:?}");
        }
        assert_eq!(builtin_scene("water").map(|s| s.0), Some("water"));
        assert!(builtin_scene("sea").is_none());
    }
}

#[cfg(test)]
#[allow(clippy::float_cmp)] // exact values are the point of these tests
mod tests {
    use super::*;
    use crate::config::{Check, to_toml};

    #[test]
    fn the_default_scene_fits_the_default_rig_and_has_the_papers_ranges() {
        let (rig, scene) = (rig(), scene());
        let mut check = Check::default();
        scene.validate_against(&rig, &mut check);
        assert!(check.problems().is_empty(), "{:?}", check.problems());
        assert_eq!([scene.poses.x_m.min, scene.poses.x_m.max], [0.0, 0.05]);
        assert_eq!([scene.poses.z_m.min, scene.poses.z_m.max], [-0.05, 0.05]);
        assert_eq!(scene.poses.theta_rad.max, std::f64::consts::PI);
        assert!(scene.rods.len() >= 3);
    }

    #[test]
    fn printed_configs_parse_back_to_the_same_value() {
        let rig2: RigConfig = parse_toml(&to_toml(&rig()), &ConfigSource::Embedded("rig"))
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(rig2, rig());
        let scene2: SceneSpec = parse_toml(&to_toml(&scene()), &ConfigSource::Embedded("scene"))
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(scene2, scene());
    }
}
