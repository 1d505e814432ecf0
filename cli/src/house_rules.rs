//! The workspace's house rules, checked on every test run:
//! - the verbs stay thin: no file of this crate's sources over [`LINES_PER_FILE`]
//!   lines, unless [`EXCEPTIONS`] names it with its reason and its own limit;
//! - the library rooms stay small: no library source file (tests apart) over
//!   [`LIBRARY_LINES_PER_FILE`] lines;
//! - the repository stands alone: no tracked file names a path outside it (a lab's
//!   clone has nothing beside it), neither a relative path that climbs out of the
//!   checkout nor an absolute path of somebody's machine.

use std::path::{Path, PathBuf};

/// The most lines a file under `cli/src` may have. A verb that needs more is doing an
/// experiment's work: move that work into `lab` (or `collector`) behind one function.
pub(crate) const LINES_PER_FILE: usize = 400;

/// Files allowed more, each with its limit and why. Empty: none needs one.
pub(crate) const EXCEPTIONS: &[(&str, usize, &str)] = &[];

/// The most lines a library source file (any crate's `src/`, its `tests.rs` and
/// `tests/` apart) may have. A file past it holds more than one idea: cut it where
/// its parts meet (the layout in docs/layout.md names the rooms).
pub(crate) const LIBRARY_LINES_PER_FILE: usize = 800;

/// The workspace root (this crate's parent).
fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap_or_else(|| panic!("{} has no parent", env!("CARGO_MANIFEST_DIR")))
        .to_path_buf()
}

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

/// Whether a source file is a test rather than library code.
fn is_test_source(relative: &Path) -> bool {
    relative.file_name().is_some_and(|n| n == "tests.rs")
        || relative.components().any(|c| c.as_os_str() == "tests")
}

/// Each library source file over [`LIBRARY_LINES_PER_FILE`], as `path: N lines`.
fn library_files_over_budget(root: &Path) -> Vec<String> {
    let mut files = Vec::new();
    let entries = std::fs::read_dir(root).unwrap_or_else(|e| panic!("{}: {e}", root.display()));
    for entry in entries {
        let dir = entry
            .unwrap_or_else(|e| panic!("{}: {e}", root.display()))
            .path();
        // A crate is a folder with a Cargo.toml; its library sources are under src/.
        if dir.join("Cargo.toml").is_file() && dir.join("src").is_dir() {
            sources(&dir.join("src"), &mut files);
        }
    }
    files.sort();
    let mut over = Vec::new();
    for path in files {
        let relative = path.strip_prefix(root).unwrap_or(&path);
        if is_test_source(relative) {
            continue;
        }
        let text =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let lines = text.lines().count();
        if lines > LIBRARY_LINES_PER_FILE {
            over.push(format!("{}: {lines} lines", relative.display()));
        }
    }
    over
}

#[test]
fn every_library_file_stays_within_its_line_budget() {
    let over = library_files_over_budget(&workspace_root());
    assert!(
        over.is_empty(),
        "library rooms stay small ({LIBRARY_LINES_PER_FILE} lines): cut the file where its \
         parts meet and say so in docs/layout.md:\n{}",
        over.join("\n")
    );
}

/// Prefixes of absolute paths that only exist on somebody's machine. Written in
/// pieces so that this file does not name them itself.
const MACHINE_PATHS: [&str; 4] = [
    concat!("/", "work/"),
    concat!("/", "root/"),
    concat!("/", "home/"),
    concat!("/", "Users/"),
];

/// The files git tracks under `root`, or, where it is not a git checkout (an
/// unpacked archive), every file below it but `target/` and hidden folders.
fn tracked_files(root: &Path) -> Vec<PathBuf> {
    let listed = std::process::Command::new("git")
        .args(["ls-files", "-z"])
        .current_dir(root)
        .output()
        .ok()
        .filter(|o| o.status.success() && !o.stdout.is_empty());
    if let Some(out) = listed {
        return out
            .stdout
            .split(|b| *b == 0)
            .filter(|p| !p.is_empty())
            .map(|p| PathBuf::from(String::from_utf8_lossy(p).into_owned()))
            .collect();
    }
    fn walk(root: &Path, dir: &Path, found: &mut Vec<PathBuf>) {
        let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
        for entry in entries.flatten() {
            let path = entry.path();
            let name = entry.file_name();
            let hidden = name.to_string_lossy().starts_with('.');
            if path.is_dir() {
                if !hidden && name != "target" {
                    walk(root, &path, found);
                }
            } else if let Ok(relative) = path.strip_prefix(root) {
                found.push(relative.to_path_buf());
            }
        }
    }
    let mut found = Vec::new();
    walk(root, root, &mut found);
    found
}

/// Where `relative` (a path with `..` in it, written in a file in folder `from`)
/// leads, as components below the root; `None` when it climbs out of the root.
fn resolve(from: &Path, relative: &str) -> Option<PathBuf> {
    let mut parts: Vec<String> = from
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    for part in relative.split('/') {
        match part {
            "" | "." => {}
            ".." => {
                parts.pop()?;
            }
            name => parts.push(name.to_owned()),
        }
    }
    Some(parts.iter().collect())
}

/// Paths that climb out on purpose: test inputs a check must refuse, as
/// (file or folder, path, why); written in pieces, as this file must not name them.
const OUTSIDE_ON_PURPOSE: [(&str, &str, &str); 2] = [
    (
        "tests/dataset.rs",
        concat!("..", "/evil"),
        "a dataset name that climbs out of the datasets folder, refused",
    ),
    (
        "tests/dataset_cases/paper/parent_path/",
        concat!("..", "/img0.png"),
        "an import whose image path climbs out of its folder, refused",
    ),
];

/// The folders a relative path in the file at `relative` may be written from: its
/// own folder, its crate's (`env!("CARGO_MANIFEST_DIR")`, `sqlx::migrate!`) and the
/// repository's root (scripts and docs name paths from there).
fn bases<'a>(root: &Path, relative: &'a Path) -> Vec<&'a Path> {
    let folder = relative.parent().unwrap_or(Path::new(""));
    let mut bases = vec![folder];
    if let Some(krate) = folder
        .ancestors()
        .find(|a| !a.as_os_str().is_empty() && root.join(a).join("Cargo.toml").is_file())
    {
        bases.push(krate);
    }
    bases.push(Path::new(""));
    bases
}

/// The paths in `text` (a file at `relative` under `root`) that lead outside the
/// repository, as `path:line: what`. A `../` path counts when it leads to no file of
/// the repository from any folder it may be written from ([`bases`]) and climbs out
/// of the root from one of them.
fn outside_paths(root: &Path, relative: &Path, text: &str) -> Vec<String> {
    let bases = bases(root, relative);
    let path_char = |c: char| c.is_ascii_alphanumeric() || "._-/~".contains(c);
    let on_purpose = |path: &str| {
        OUTSIDE_ON_PURPOSE
            .iter()
            .any(|(file, p, _)| relative.starts_with(file) && path == *p)
    };
    let mut found = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let at = |what: &str| format!("{}:{}: {what}", relative.display(), n + 1);
        for prefix in MACHINE_PATHS {
            if line.contains(prefix) {
                found.push(at(&format!("an absolute path of a machine ({prefix}…)")));
            }
        }
        let mut rest = line;
        while let Some(i) = rest.find("../") {
            // The whole path: back to its start, forward to its end.
            let start = rest[..i].rfind(|c: char| !path_char(c)).map_or(0, |j| {
                j + rest[j..].chars().next().map_or(1, char::len_utf8)
            });
            let end = rest[i..]
                .find(|c: char| !path_char(c))
                .map_or(rest.len(), |j| i + j);
            let path = &rest[start..end];
            rest = &rest[end..];
            // `../` alone names a folder in prose, not a file to bring in.
            if !path.split('/').any(|p| !matches!(p, "" | "." | "..")) || on_purpose(path) {
                continue;
            }
            let leads: Vec<Option<PathBuf>> = bases.iter().map(|b| resolve(b, path)).collect();
            let inside = leads.iter().flatten().any(|p| root.join(p).exists());
            if !inside && leads.iter().any(Option::is_none) {
                found.push(at(path));
            }
        }
    }
    found
}

#[test]
fn no_tracked_file_names_a_path_outside_the_repository() {
    let root = workspace_root();
    let mut found = Vec::new();
    for relative in tracked_files(&root) {
        // Binary files (fonts, PNGs) name no paths.
        if let Ok(text) = std::fs::read_to_string(root.join(&relative)) {
            found.extend(outside_paths(&root, &relative, &text));
        }
    }
    assert!(
        found.is_empty(),
        "the repository stands alone (a lab's clone has nothing beside it): bring what \
         these name into the repository and point at it there:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_outside_check_sees_paths_that_leave_the_repository() {
    let root = workspace_root();
    let up = "../";
    let check = |file: &str, text: &str| outside_paths(&root, Path::new(file), text);
    // Beside the checkout, from the root and from a folder.
    assert_eq!(
        check("README.md", &format!("see `{up}beside/MAP.md`")),
        [format!("README.md:1: {up}beside/MAP.md")]
    );
    assert_eq!(
        check("docs/a.md", &format!("x\n[m]({up}{up}beside/P.md)")).len(),
        1
    );
    // A script names paths from the root: leading nowhere from its folder and out of
    // the root is outside.
    assert_eq!(
        check(".ci/run", &format!("# from {up}beside/rigs")).len(),
        1
    );
    // An absolute path of somebody's machine.
    assert_eq!(check("a.rs", &format!("{}x/y", MACHINE_PATHS[0])).len(), 1);
    // Inside the repository: fine, from the file's folder.
    assert!(
        check(
            "docs/bench/README.md",
            &format!("[t]({up}{up}trainer/README.md)")
        )
        .is_empty()
    );
    assert!(
        check(
            "tests/e.rs",
            &format!("#[path = \"{up}drivers/src/lib.rs\"]")
        )
        .is_empty()
    );
    assert!(check("README.md", "no paths here, ../ alone is a folder").is_empty());
    // From the crate's folder (`CARGO_MANIFEST_DIR`, `sqlx::migrate!`).
    assert!(
        check(
            "store/src/lib.rs",
            &format!("migrate!(\"{up}migrations/sqlite\")")
        )
        .is_empty()
    );
    assert!(
        check(
            "sim/src/tests.rs",
            &format!("env!(\"CARGO_MANIFEST_DIR\"), \"/{up}scenes/water.toml\"")
        )
        .is_empty()
    );
    // A path that climbs out on purpose is named where the check reads it.
    assert!(check("tests/dataset.rs", &format!("\"{up}evil\"")).is_empty());
    assert_eq!(check("tests/other.rs", &format!("\"{up}evil\"")).len(), 1);
}

#[test]
fn the_library_budget_skips_tests_and_sees_a_long_file() {
    assert!(is_test_source(Path::new("sim/src/grasp/tests.rs")));
    assert!(is_test_source(Path::new("grasp/tests/soft.rs")));
    assert!(!is_test_source(Path::new("store/src/lib.rs")));
    let dir = std::env::temp_dir().join(format!("softtouch-house-lib-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("krate/src/tests")).unwrap_or_else(|e| panic!("{e}"));
    std::fs::write(dir.join("krate/Cargo.toml"), "").unwrap_or_else(|e| panic!("{e}"));
    let long = "\n".repeat(LIBRARY_LINES_PER_FILE + 1);
    for file in [
        "krate/src/big.rs",
        "krate/src/tests.rs",
        "krate/src/tests/x.rs",
    ] {
        std::fs::write(dir.join(file), &long).unwrap_or_else(|e| panic!("{e}"));
    }
    std::fs::write(dir.join("krate/src/small.rs"), "\n").unwrap_or_else(|e| panic!("{e}"));
    let over = library_files_over_budget(&dir);
    std::fs::remove_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        over,
        [format!(
            "krate/src/big.rs: {} lines",
            LIBRARY_LINES_PER_FILE + 1
        )]
    );
}
