//! The rule that keeps the verbs thin, checked on every test run: no file of this
//! crate's sources over [`LINES_PER_FILE`] lines, unless [`EXCEPTIONS`] names it with
//! its reason and its own limit.

use std::path::{Path, PathBuf};

/// The most lines a file under `cli/src` may have. A verb that needs more is doing an
/// experiment's work: move that work into `lab` (or `collector`) behind one function.
pub(crate) const LINES_PER_FILE: usize = 400;

/// Files allowed more, each with its limit and why. Empty: none needs one.
pub(crate) const EXCEPTIONS: &[(&str, usize, &str)] = &[];

fn sources(dir: &Path, found: &mut Vec<PathBuf>) {
    let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    for entry in entries {
        let path = entry
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .path();
        if path.is_dir() {
            sources(&path, found);
        } else if path.extension().is_some_and(|x| x == "rs") {
            found.push(path);
        }
    }
}

/// Each file over its limit, as `path: N lines (limit L)`.
fn over_budget(root: &Path) -> Vec<String> {
    let mut files = Vec::new();
    sources(root, &mut files);
    files.sort();
    let mut over = Vec::new();
    for path in files {
        let text =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let name = path
            .strip_prefix(root)
            .unwrap_or(&path)
            .display()
            .to_string();
        let limit = EXCEPTIONS
            .iter()
            .find(|(file, _, _)| *file == name)
            .map_or(LINES_PER_FILE, |(_, limit, _)| *limit);
        let lines = text.lines().count();
        if lines > limit {
            over.push(format!("cli/src/{name}: {lines} lines (limit {limit})"));
        }
    }
    over
}

#[test]
fn every_verb_file_stays_within_its_line_budget() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let over = over_budget(&root);
    assert!(
        over.is_empty(),
        "verbs stay thin (cli/src/lib.rs): move the experiment's work into the library, \
         or list the file in house_rules::EXCEPTIONS with its reason:\n{}",
        over.join("\n")
    );
}

#[test]
fn the_budget_check_sees_a_file_over_it() {
    let dir = std::env::temp_dir().join(format!("softtouch-house-rules-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("nested")).unwrap_or_else(|e| panic!("{e}"));
    std::fs::write(dir.join("short.rs"), "fn a() {}\n").unwrap_or_else(|e| panic!("{e}"));
    std::fs::write(dir.join("nested/long.rs"), "\n".repeat(LINES_PER_FILE + 1))
        .unwrap_or_else(|e| panic!("{e}"));
    let over = over_budget(&dir);
    std::fs::remove_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        over,
        [format!(
            "cli/src/nested/long.rs: {} lines (limit {LINES_PER_FILE})",
            LINES_PER_FILE + 1
        )]
    );
}
