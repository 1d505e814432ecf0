//! Every malformed config under `tests/cases/` is rejected with the error its first
//! line (`# expect: ...`) names. Scenes are also checked against the default rig.

use softtouch_schemas::config::{Check, load_toml};
use softtouch_schemas::{ConfigSource, RigConfig, SceneSpec, defaults};
use std::path::{Path, PathBuf};

fn cases(kind: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/cases")
        .join(kind);
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no cases in {}", dir.display());
    files
}

fn expectation(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    text.lines()
        .next()
        .and_then(|l| l.strip_prefix("# expect: "))
        .unwrap_or_else(|| panic!("{} has no `# expect:` first line", path.display()))
        .to_owned()
}

/// `None` when the error is the expected one and names the file; else what went wrong.
fn mismatch(path: &Path, message: &str) -> Option<String> {
    let expect = expectation(path);
    if !message.contains(&expect) {
        return Some(format!(
            "{}:\n  expected an error containing: {expect}\n  got: {message}",
            path.display()
        ));
    }
    if !message.contains(&path.display().to_string()) {
        return Some(format!(
            "{}: error does not name the file: {message}",
            path.display()
        ));
    }
    None
}

fn report(failures: &[String]) {
    assert!(
        failures.is_empty(),
        "{} case(s) failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn every_malformed_rig_case_is_rejected_with_its_expected_error() {
    let failures: Vec<String> = cases("rig")
        .iter()
        .filter_map(|path| match load_toml::<RigConfig>(path) {
            Ok(_) => Some(format!("{} was accepted", path.display())),
            Err(e) => mismatch(path, &e.to_string()),
        })
        .collect();
    report(&failures);
}

#[test]
fn every_malformed_scene_case_is_rejected_with_its_expected_error() {
    let rig = defaults::rig();
    let failures: Vec<String> = cases("scene")
        .iter()
        .filter_map(|path| {
            let message = match load_toml::<SceneSpec>(path) {
                Err(e) => e.to_string(),
                Ok(scene) => {
                    let mut check = Check::default();
                    scene.validate_against(&rig, &mut check);
                    match check.finish(&ConfigSource::File(path.clone())) {
                        Ok(()) => return Some(format!("{} was accepted", path.display())),
                        Err(e) => e.to_string(),
                    }
                }
            };
            mismatch(path, &message)
        })
        .collect();
    report(&failures);
}
