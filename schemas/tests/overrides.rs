//! `--set PATH=VALUE` and `--sweep PATH=V1,V2,…` on the shipped scenes: paths through
//! tables and lists of tables, values checked as the file's are, and every malformed
//! input refused with a message that names it.

use softtouch_schemas::config::{ConfigSource, load_toml};
use softtouch_schemas::overrides::{Override, Sweep, applies_to, apply, astray, shown};
use softtouch_schemas::{Effect, SceneSpec};

fn water() -> SceneSpec {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    load_toml(&root.join("scenes/grasp-water.toml")).expect("the shipped water scene loads")
}

fn set(text: &str) -> Override {
    text.parse().unwrap_or_else(|e| panic!("{text}: {e}"))
}

fn source() -> ConfigSource {
    ConfigSource::Embedded("grasp-water")
}

#[test]
fn a_value_is_set_by_an_entrys_name_or_kind_or_index() {
    let scene = water();
    let out = apply(
        &scene,
        &[
            set("objects.bottle.wet_friction=0.2"),
            set("effects.object_flow.mean_m_s = 0.1"),
            set("objects.0.drag_coefficient=0.9"),
        ],
        &source(),
    )
    .expect("applies");
    let bottle = out.object("bottle").expect("bottle");
    assert_eq!(
        bottle.wet_friction.map(f64::to_bits),
        Some(0.2_f64.to_bits())
    );
    let flow = out.effect("object_flow").expect("flow");
    assert!(matches!(flow, Effect::ObjectFlow { mean_m_s, .. } if (*mean_m_s - 0.1).abs() < 1e-12));
    // An optional field the file leaves out is set too.
    assert_eq!(
        out.objects[0].drag_coefficient.map(f64::to_bits),
        Some(0.9_f64.to_bits())
    );
    // Nothing else moved.
    let mut back = out.clone();
    back.objects = scene.objects.clone();
    back.effects = scene.effects.clone();
    assert_eq!(back, scene);
    // An integer is a number of the field's kind.
    let out = apply(&scene, &[set("objects.bottle.wet_friction=1")], &source()).expect("applies");
    assert_eq!(
        out.object("bottle")
            .and_then(|o| o.wet_friction)
            .map(f64::to_bits),
        Some(1.0_f64.to_bits())
    );
    assert!(applies_to(&scene, "objects.bottle.wet_friction"));
    assert!(!applies_to(&scene, "objects.vase.wet_friction"));
}

#[test]
fn a_path_that_leads_nowhere_says_where_it_went_astray() {
    let scene = water();
    let err = |o: &str| {
        apply(&scene, &[set(o)], &source())
            .expect_err(o)
            .to_string()
    };
    let e = err("objects.vase.wet_friction=0.2");
    assert!(
        e.contains("no entry `vase` in `objects`") && e.contains("bottle"),
        "{e}"
    );
    let e = err("effects.object_flw.mean_m_s=0.1");
    assert!(
        e.contains("no entry `object_flw`") && e.contains("object_flow"),
        "{e}"
    );
    let e = err("nothing.here=1");
    assert!(e.contains("no `nothing`"), "{e}");
    // A key the config does not know is refused as in the file.
    let e = err("objects.bottle.wet_fricton=0.2");
    assert!(e.contains("unknown field `wet_fricton`"), "{e}");
    // Inside a value.
    let e = err("objects.bottle.wet_friction.x=1");
    assert!(e.contains("not a table"), "{e}");
    assert!(astray(&scene, "objects.bottle.wet_friction").is_none());
    assert!(astray(&scene, "objects.vase.x").is_some());
}

#[test]
fn a_value_is_checked_as_the_files_is() {
    let scene = water();
    let err = |o: &str| {
        apply(&scene, &[set(o)], &source())
            .expect_err(o)
            .to_string()
    };
    let e = err("objects.bottle.wet_friction=abc");
    assert!(
        e.contains("field `objects.bottle.wet_friction`")
            && e.contains("--set objects.bottle.wet_friction=abc"),
        "{e}"
    );
    // A value the checks refuse names the object and the --set, not `objects[3]`.
    let e = err("objects.bottle.wet_friction=-1");
    assert!(
        e.contains("field `objects.bottle.wet_friction`")
            && e.contains("(with --set objects.bottle.wet_friction=-1)")
            && !e.contains("objects[3]"),
        "{e}"
    );
    let e = err("effects.object_flow.period_s=0");
    assert!(e.contains("period_s"), "{e}");
    let e = err("effects.object_flow.mean_m_s=nan");
    assert!(e.contains("mean_m_s"), "{e}");
    // A 20 000-character value is not echoed whole.
    let long = format!("objects.bottle.surface={}", "x".repeat(20_000));
    let e = format!("{}", set(&long));
    assert!(e.len() > 20_000, "the value itself is kept");
    let e = err(&format!(
        "objects.bottle.wet_friction={}",
        "9".repeat(20_000)
    ));
    assert!(e.len() < 2_000, "{} characters", e.len());
}

#[test]
fn malformed_flags_are_refused_by_name() {
    for (text, says) in [
        ("objects.bottle.wet_friction", "expected PATH=VALUE"),
        ("=0.2", "dotted path"),
        ("objects..wet_friction=0.2", "dotted path"),
        ("objects.bottle.wet_friction=", "expected a value"),
        ("objects.bottle.wet_friction=  ", "expected a value"),
    ] {
        let e = text.parse::<Override>().expect_err(text);
        assert!(e.contains(says), "{text}: {e}");
    }
    for (text, says) in [
        ("objects.bottle.wet_friction", "expected PATH=V1,V2"),
        ("objects.bottle.wet_friction=0.2", "at least two values"),
        ("objects.bottle.wet_friction=0.2,,0.3", "none empty"),
        ("objects.bottle.wet_friction=0.2,0.2", "given twice"),
    ] {
        let e = text.parse::<Sweep>().expect_err(text);
        assert!(e.contains(says), "{text}: {e}");
    }
    let many = format!(
        "sigma_mm={}",
        (0..51).map(|i| i.to_string()).collect::<Vec<_>>().join(",")
    );
    assert!(
        many.parse::<Sweep>()
            .expect_err("51")
            .contains("at most 50")
    );
    let sweep: Sweep = "objects.bottle.wet_friction=0.05, 0.1,0.5"
        .parse()
        .expect("parses");
    assert_eq!(sweep.values.len(), 3);
    assert_eq!(shown(&sweep.values[1]), "0.1");
    assert_eq!(
        sweep.at(2).map(|o| o.to_string()).as_deref(),
        Some("objects.bottle.wet_friction=0.5")
    );
    assert!(sweep.at(3).is_none());
    // A word is text; TOML is TOML.
    assert_eq!(shown(&set("name=tank two").value), "tank two");
    assert_eq!(set("x=[1, 2]").value.as_array().map(Vec::len), Some(2));
}
