//! The scene's parsing and checks on malformed input.

use super::*;
use crate::config::{ConfigSource, parse_toml};

fn scene_with_object(object: &str) -> Result<SceneSpec, String> {
    let text = format!("{}\n[[objects]]\n{object}\n", crate::defaults::SCENE_TOML);
    parse_toml::<SceneSpec>(&text, &ConfigSource::Embedded("test")).map_err(|e| e.to_string())
}

const BALL: &str = "shape = \"circle\"\nwidth_m = 0.04\nmass_kg = 0.05\nfriction = 0.5\n";

#[test]
fn an_unknown_key_inside_a_profile_is_refused_for_every_kind() {
    let ok = scene_with_object(&format!(
        "name = \"ball\"\n{BALL}profile = {{ kind = \"sphere\" }}"
    ));
    assert!(ok.is_ok(), "{ok:?}");
    for profile in [
        "{ kind = \"sphere\", height_m = 0.05 }",
        "{ kind = \"prism\", height_m = 0.05, heigth_m = 0.05 }",
        "{ kind = \"taper\", height_m = 0.05, top_width_m = 0.02, top = 1 }",
    ] {
        let e = scene_with_object(&format!("name = \"ball\"\n{BALL}profile = {profile}"))
            .expect_err(profile);
        assert!(e.contains("unknown field"), "{profile}: {e}");
    }
}

#[test]
fn names_that_could_never_be_chosen_are_refused_by_field() {
    for (name, says) in [
        ("a,b", "contains a comma"),
        ("tab\\tname", "control character"),
        (" ball", "white space"),
    ] {
        let e = scene_with_object(&format!(
            "name = \"{name}\"\n{BALL}profile = {{ kind = \"sphere\" }}"
        ))
        .expect_err(name);
        assert!(
            e.contains("objects[0].name") && e.contains(says),
            "{name}: {e}"
        );
    }
    assert_eq!(name_problem("oval-tube_2 (blue)"), None);
}

#[test]
fn wet_contact_needs_every_objects_wet_friction_and_takes_no_keys() {
    let wet = |object: &str, effect: &str| {
        let text = format!(
            "{}\n[[effects]]\n{effect}\n\n[[objects]]\n{object}\n",
            crate::defaults::SCENE_TOML
        );
        parse_toml::<SceneSpec>(&text, &ConfigSource::Embedded("test")).map_err(|e| e.to_string())
    };
    let ball = format!("name = \"ball\"\n{BALL}profile = {{ kind = \"sphere\" }}");
    let e = wet(&ball, "kind = \"wet_contact\"").expect_err("no wet_friction");
    assert!(
        e.contains("objects[0].wet_friction") && e.contains("declares wet_contact"),
        "{e}"
    );
    let with = format!("{ball}\nwet_friction = 0.05\nsurface = \"glass\"");
    assert!(wet(&with, "kind = \"wet_contact\"").is_ok());
    let e = wet(&with, "kind = \"wet_contact\"\nfactor = 0.1").expect_err("a key");
    assert!(e.contains("unknown field"), "{e}");
    let e = wet(
        &format!("{ball}\nwet_friction = 3.0"),
        "kind = \"wet_contact\"",
    )
    .expect_err("out of range");
    assert!(e.contains("objects[0].wet_friction"), "{e}");
    // Without the effect a wet friction is only read, never required.
    assert!(scene_with_object(&ball).is_ok());
}

#[test]
fn support_added_mass_and_gust_spectra_are_checked_by_field() {
    let scene = |object: &str, effect: &str| {
        let text = format!(
            "{}\n[[effects]]\n{effect}\n\n[[objects]]\n{object}\n",
            crate::defaults::SCENE_TOML
        );
        parse_toml::<SceneSpec>(&text, &ConfigSource::Embedded("test")).map_err(|e| e.to_string())
    };
    let ball = format!("name = \"ball\"\n{BALL}profile = {{ kind = \"sphere\" }}");
    let flow = "kind = \"object_flow\"\nfluid_density_kg_m3 = 1000.0\nmean_m_s = 0.05";
    // Accepted: a support, a rolling ball's own value, added mass, a steady
    // current, the three-sine gusts, a spectrum.
    for (object, effect) in [
        (
            ball.clone(),
            "kind = \"object_support\"\nfriction = 0.3".to_owned(),
        ),
        (
            format!("{ball}\nsupport_friction = 0.02"),
            "kind = \"object_support\"\nfriction = 0.3".to_owned(),
        ),
        (
            ball.clone(),
            "kind = \"object_added_mass\"\nfluid_density_kg_m3 = 1000.0".to_owned(),
        ),
        (ball.clone(), flow.to_owned()),
        (
            ball.clone(),
            format!("{flow}\ngust_m_s = 0.1\nperiod_s = 1.5"),
        ),
        (
            ball.clone(),
            format!(
                "{flow}\nspectrum = [{{ period_s = 0.75, amplitude_m_s = 0.03 }}, {{ period_s = 3.0, amplitude_m_s = 0.02 }}]"
            ),
        ),
    ] {
        let parsed = scene(&object, &effect);
        assert!(parsed.is_ok(), "{effect}: {parsed:?}");
    }
    // Refused, naming the field.
    for (object, effect, field) in [
        (
            ball.clone(),
            "kind = \"object_support\"\nfriction = -0.1".to_owned(),
            ".friction",
        ),
        (
            ball.clone(),
            "kind = \"object_support\"".to_owned(),
            "friction",
        ),
        (
            ball.clone(),
            "kind = \"object_support\"\nfriction = 0.3\nwet = 0.1".to_owned(),
            "unknown field",
        ),
        (
            format!("{ball}\nsupport_friction = nan"),
            "kind = \"object_support\"\nfriction = 0.3".to_owned(),
            "objects[0].support_friction",
        ),
        (
            ball.clone(),
            "kind = \"object_added_mass\"\nfluid_density_kg_m3 = -1.0".to_owned(),
            "fluid_density_kg_m3",
        ),
        (
            ball.clone(),
            format!(
                "{flow}\ngust_m_s = 0.1\nspectrum = [{{ period_s = 1.0, amplitude_m_s = 0.1 }}]"
            ),
            "not both",
        ),
        (
            ball.clone(),
            format!("{flow}\nspectrum = [{{ period_s = 0.0, amplitude_m_s = 0.1 }}]"),
            "spectrum[0].period_s",
        ),
        (
            ball.clone(),
            format!("{flow}\nspectrum = [{{ period_s = 1.0, amplitude_m_s = -0.1 }}]"),
            "spectrum[0].amplitude_m_s",
        ),
        (
            ball.clone(),
            format!("{flow}\nspectrum = []"),
            "expected at least one component",
        ),
        (
            ball.clone(),
            format!("{flow}\nspectrum = [{{ period_s = 1.0, amplitude = 0.1 }}]"),
            "unknown field",
        ),
        (
            ball.clone(),
            format!("{flow}\nspectrum = {{ period_s = 1.0 }}"),
            "expected a sequence",
        ),
    ] {
        let Err(e) = scene(&object, &effect) else {
            panic!("{effect}: accepted");
        };
        assert!(e.contains(field), "{effect}: {e}");
    }
}

/// A scene has one fluid: effects that name different densities are refused, naming
/// the second effect's field and the first effect with its value.
#[test]
fn every_effect_names_the_same_fluid_density() {
    let scene = |effects: &str| {
        let text = format!("{}\n{effects}\n", crate::defaults::SCENE_TOML);
        parse_toml::<SceneSpec>(&text, &ConfigSource::Embedded("test")).map_err(|e| e.to_string())
    };
    let effect = |kind: &str, rho: &str| {
        format!("[[effects]]\nkind = \"{kind}\"\nfluid_density_kg_m3 = {rho}\n")
    };
    let same = format!(
        "{}{}{}",
        effect("object_buoyancy", "1000.0"),
        effect("object_drag", "1000.0"),
        effect("object_added_mass", "1000.0")
    );
    assert!(scene(&same).is_ok(), "{:?}", scene(&same));
    let sea = format!(
        "{}{}mean_m_s = 0.05\n",
        effect("object_buoyancy", "1000.0"),
        effect("object_flow", "1025.0")
    );
    let err = scene(&sea).expect_err("two fluids");
    // The default scene's own effects come first: the buoyancy is one past them.
    assert!(
        err.contains("effects[2].fluid_density_kg_m3")
            && err.contains("1025 kg/m³")
            && err.contains("(`object_buoyancy`) declares 1000 kg/m³"),
        "{err}"
    );
    // Any two that differ, not only the first pair.
    let third = format!("{same}{}mean_m_s = 0.05\n", effect("object_flow", "998.0"));
    let err = scene(&third).expect_err("a third fluid");
    assert!(err.contains("998 kg/m³"), "{err}");
}
