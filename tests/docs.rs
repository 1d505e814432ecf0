//! The docs and the help texts against the program: every `softtouch` command in a
//! fenced block of the README, `docs/`, TESTING.md and the trainer's README, and every
//! example line of every `--help`, parses with the program's own parser; the quick
//! start and the read-only examples run. A verb or flag renamed without its docs fails
//! here.

use crate::common::{ok, softtouch, tempdir};
use clap::{CommandFactory, Parser};
use softtouch_cli::Cli;
use std::path::{Path, PathBuf};

/// The repository's root (the CLI crate's parent).
pub(crate) fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap_or_else(|| panic!("the CLI crate has a parent folder"))
        .to_path_buf()
}

/// The Markdown a person reads: the README, TESTING.md, the trainer's README and every
/// page under `docs/`.
fn doc_files() -> Vec<PathBuf> {
    let root = root();
    let mut files = vec![
        root.join("README.md"),
        root.join("TESTING.md"),
        root.join("trainer/README.md"),
    ];
    let mut pages: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .unwrap_or_else(|e| panic!("docs/: {e}"))
        .map(|e| e.unwrap_or_else(|e| panic!("docs/: {e}")).path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    pages.sort();
    files.extend(pages);
    files
}

/// Each doc's name (from the repository's root), folder and text.
pub(crate) fn doc_texts() -> Vec<(String, PathBuf, String)> {
    doc_files()
        .into_iter()
        .map(|file| {
            let text = std::fs::read_to_string(&file)
                .unwrap_or_else(|e| panic!("{}: {e}", file.display()));
            let name = file
                .strip_prefix(root())
                .unwrap_or(&file)
                .display()
                .to_string();
            let dir = file
                .parent()
                .unwrap_or_else(|| Path::new("."))
                .to_path_buf();
            (name, dir, text)
        })
        .collect()
}

/// Words of a shell command, with single and double quotes (no expansion).
fn shell_words(line: &str) -> Vec<String> {
    let mut words = Vec::new();
    let mut word = String::new();
    let mut quote: Option<char> = None;
    let mut in_word = false;
    for c in line.chars() {
        match quote {
            Some(q) if c == q => quote = None,
            Some(_) => word.push(c),
            None if c == '"' || c == '\'' => {
                quote = Some(c);
                in_word = true;
            }
            None if c.is_whitespace() => {
                if in_word {
                    words.push(std::mem::take(&mut word));
                    in_word = false;
                }
            }
            None => {
                word.push(c);
                in_word = true;
            }
        }
    }
    if in_word {
        words.push(word);
    }
    words
}

/// The `softtouch` invocations of one shell line: `cargo run --release --` is the
/// program too; a comment, a pipe, a redirection and what follows `&&` or `;` are cut
/// off (and the part after `&&` read as its own command).
fn invocations(line: &str) -> Vec<Vec<String>> {
    let line = line.trim().trim_start_matches("$ ");
    let mut found = Vec::new();
    for part in line.split("&&").flat_map(|p| p.split(';')) {
        let part = part.replace("cargo run --release --", "softtouch");
        let words = shell_words(&part);
        let Some(start) = words.iter().position(|w| w == "softtouch") else {
            continue;
        };
        let mut args = Vec::new();
        for w in &words[start..] {
            if w.starts_with('#') || w == "|" || w.starts_with('>') || w.starts_with("2>") {
                break;
            }
            args.push(w.clone());
        }
        if args.len() > 1 {
            found.push(args);
        }
    }
    found
}

/// One step of a fenced shell block: a `softtouch` command, or an `export NAME=VALUE`
/// that the commands after it see.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Step {
    Run(Vec<String>),
    Env(String, String),
}

/// Every step in the fenced shell blocks of a Markdown text, with its line; a line
/// ending in `\` continues on the next.
pub(crate) fn fenced_steps(text: &str) -> Vec<(usize, Step)> {
    let mut found = Vec::new();
    let mut in_shell = None::<bool>;
    let mut pending = String::new();
    let mut pending_line = 0;
    for (i, raw) in text.lines().enumerate() {
        let trimmed = raw.trim();
        if let Some(lang) = trimmed.strip_prefix("```") {
            in_shell = match in_shell {
                Some(_) => None,
                None => Some(matches!(lang, "" | "sh" | "bash" | "console" | "shell")),
            };
            continue;
        }
        if in_shell != Some(true) {
            continue;
        }
        if pending.is_empty() {
            pending_line = i + 1;
        }
        match trimmed.strip_suffix('\\') {
            Some(head) => {
                pending.push_str(head);
                pending.push(' ');
            }
            None => {
                pending.push_str(trimmed);
                let export = pending
                    .strip_prefix("export ")
                    .and_then(|rest| shell_words(rest.split(" #").next()?).into_iter().next())
                    .and_then(|word| {
                        let (name, value) = word.split_once('=')?;
                        Some(Step::Env(name.to_owned(), value.to_owned()))
                    });
                match export {
                    Some(step) => found.push((pending_line, step)),
                    None => found.extend(
                        invocations(&pending)
                            .into_iter()
                            .map(|args| (pending_line, Step::Run(args))),
                    ),
                }
                pending.clear();
            }
        }
    }
    found
}

/// Every `softtouch` command in the fenced shell blocks of a Markdown text, with its line.
fn fenced_commands(text: &str) -> Vec<(usize, Vec<String>)> {
    fenced_steps(text)
        .into_iter()
        .filter_map(|(line, step)| match step {
            Step::Run(args) => Some((line, args)),
            Step::Env(..) => None,
        })
        .collect()
}

/// The commands named in the prose of a Markdown text, outside fenced blocks: code
/// spans that start with `softtouch ` and hold no synopsis (`[…]`, `|`, `…`, `<…>`).
fn inline_commands(text: &str) -> Vec<(usize, Vec<String>)> {
    let mut found = Vec::new();
    let mut fenced = false;
    for (i, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        let parts: Vec<&str> = line.split('`').collect();
        for (k, span) in parts.iter().enumerate() {
            // A span the line wraps (its closing backtick on the next line) is left out.
            let closed = k + 1 < parts.len();
            let synopsis = span.contains(['[', '|', '…', '<']);
            if k % 2 == 1 && closed && span.starts_with("softtouch ") && !synopsis {
                found.extend(invocations(span).into_iter().map(|args| (i + 1, args)));
            }
        }
    }
    found
}

/// Every example line (`  softtouch …`) of a command's help and its subcommands'.
pub(crate) fn help_examples(
    command: &clap::Command,
    path: &str,
    found: &mut Vec<(String, Vec<String>)>,
) {
    for text in [command.get_after_help(), command.get_after_long_help()]
        .into_iter()
        .flatten()
    {
        for line in text.to_string().lines() {
            if line.trim_start().starts_with("softtouch ") {
                found.extend(
                    invocations(line)
                        .into_iter()
                        .map(|args| (path.to_owned(), args)),
                );
            }
        }
    }
    for sub in command.get_subcommands() {
        help_examples(sub, &format!("{path} {}", sub.get_name()), found);
    }
}

/// Why the program's parser refuses these arguments, or `None` where it takes them
/// (printing help or the version counts as taking them).
fn refused(args: &[String]) -> Option<String> {
    match Cli::try_parse_from(args) {
        Ok(_) => None,
        Err(e)
            if matches!(
                e.kind(),
                clap::error::ErrorKind::DisplayHelp | clap::error::ErrorKind::DisplayVersion
            ) =>
        {
            None
        }
        Err(e) => Some(e.to_string()),
    }
}

#[test]
fn every_command_in_the_docs_parses() {
    let mut seen = 0;
    let mut wrong = Vec::new();
    for (name, _, text) in doc_texts() {
        for (line, args) in fenced_commands(&text) {
            seen += 1;
            if let Some(why) = refused(&args) {
                wrong.push(format!("{name}:{line}: `{}`\n  {why}", args.join(" ")));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "commands in the docs the program refuses:\n{}",
        wrong.join("\n")
    );
    // The README's quick start alone shows nine: a harness that found none is broken.
    assert!(seen >= 20, "only {seen} commands found in the docs");
}

/// A verb or flag the prose names must exist; what it leaves out (a required flag,
/// the subcommand of a group) may be.
#[test]
fn every_command_named_in_the_docs_prose_exists() {
    use clap::error::ErrorKind;
    let mut seen = 0;
    let mut wrong = Vec::new();
    for (name, _, text) in doc_texts() {
        for (line, args) in inline_commands(&text) {
            seen += 1;
            let Err(e) = Cli::try_parse_from(&args) else {
                continue;
            };
            let left_out = matches!(
                e.kind(),
                ErrorKind::MissingRequiredArgument
                    | ErrorKind::MissingSubcommand
                    | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
                    | ErrorKind::DisplayHelp
            );
            if !left_out {
                wrong.push(format!("{name}:{line}: `{}`\n  {e}", args.join(" ")));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "commands named in the docs the program does not have:\n{}",
        wrong.join("\n")
    );
    assert!(seen >= 40, "only {seen} commands named in the docs' prose");
}

#[test]
fn every_relative_link_in_the_docs_leads_to_a_file() {
    let mut wrong = Vec::new();
    for (name, dir, text) in doc_texts() {
        for (i, line) in text.lines().enumerate() {
            for piece in line.split("](").skip(1) {
                let Some(target) = piece.split(')').next() else {
                    continue;
                };
                let path = target.split('#').next().unwrap_or_default();
                if path.is_empty() || path.contains("://") {
                    continue;
                }
                if !dir.join(path).exists() {
                    wrong.push(format!("{name}:{}: {target}", i + 1));
                }
            }
        }
    }
    assert!(wrong.is_empty(), "links to nothing:\n{}", wrong.join("\n"));
}

#[test]
fn every_example_in_the_help_parses() {
    let mut examples = Vec::new();
    help_examples(&Cli::command(), "softtouch", &mut examples);
    let wrong: Vec<String> = examples
        .iter()
        .filter_map(|(at, args)| {
            refused(args).map(|why| format!("{at} --help: `{}`\n  {why}", args.join(" ")))
        })
        .collect();
    assert!(
        wrong.is_empty(),
        "examples in --help the program refuses:\n{}",
        wrong.join("\n")
    );
    assert!(
        examples.len() >= 40,
        "only {} examples found",
        examples.len()
    );
}

#[test]
fn the_harness_reads_shell_lines_as_a_shell_would() {
    let words = |l: &str| invocations(l);
    assert_eq!(
        words("cargo run --release -- status 1            # counts"),
        [["softtouch", "status", "1"]]
    );
    assert_eq!(
        words("softtouch db init && softtouch collect --samples 15 --seed 1"),
        [
            vec!["softtouch", "db", "init"],
            vec!["softtouch", "collect", "--samples", "15", "--seed", "1"]
        ]
    );
    assert_eq!(
        words(r#"/usr/bin/time -f "%e s, %M KB" softtouch report --out r.html > log"#),
        [["softtouch", "report", "--out", "r.html"]]
    );
    assert_eq!(
        words("$ softtouch config show rig > rig.toml"),
        [["softtouch", "config", "show", "rig"]]
    );
    assert!(words("createdb -h db.lab -U lab softtouch").is_empty());
    let md = "text\n```sh\nsofttouch report --out a.html \\\n    --runs 3\n```\n```toml\nsofttouch = 1\n```\n";
    assert_eq!(
        fenced_commands(md),
        [(
            3,
            vec![
                "softtouch".into(),
                "report".into(),
                "--out".into(),
                "a.html".into(),
                "--runs".into(),
                "3".into()
            ]
        )]
    );
    assert_eq!(
        fenced_steps(
            "```sh\nexport SOFTTOUCH_DB=postgres://lab@db.lab/x   # each rig\nsofttouch runs\n```\n"
        ),
        [
            (
                2,
                Step::Env("SOFTTOUCH_DB".into(), "postgres://lab@db.lab/x".into())
            ),
            (3, Step::Run(vec!["softtouch".into(), "runs".into()]))
        ]
    );
    let prose = "run `softtouch grasp trials --model NAME`, see `softtouch results [list|show ID]`\n```sh\n`softtouch nope`\n```\nwrapped `softtouch train --dataset\nWATER`\n";
    assert_eq!(
        inline_commands(prose),
        [(
            1,
            vec![
                "softtouch".into(),
                "grasp".into(),
                "trials".into(),
                "--model".into(),
                "NAME".into()
            ]
        )]
    );
    // A renamed flag is refused, so a doc that drifts fails.
    assert!(refused(&words("softtouch collect --sample 3")[0]).is_some());
    assert!(refused(&words("softtouch collect --samples 3")[0]).is_none());
}

/// The read-only examples the README shows run, with the output they promise.
#[test]
fn the_readme_quick_looks_run() {
    let dir = tempdir();
    let d = dir.path();
    let rig = ok(&softtouch(d, &["config", "show", "rig"]));
    assert!(rig.contains("[arm]"), "{rig}");
    let out = ok(&softtouch(
        d,
        &[
            "sim",
            "render",
            "--pose",
            "0.03,0.01,1.2",
            "--out",
            "frame.png",
        ],
    ));
    assert!(d.join("frame.png").is_file(), "{out}");
    let help = ok(&softtouch(d, &["--help"]));
    for verb in ["collect", "dataset", "train", "grasp", "report", "results"] {
        assert!(help.contains(verb), "--help lists `{verb}`: {help}");
    }
}

/// The README's commands, top to bottom, in one folder: collect, status, render, the
/// configs, a dataset, training, evaluation, the grasp trials and the report; each must
/// exit 0 (`#[ignore]`d: about 1.5 minutes on 2 cores, 91 s here).
#[test]
#[ignore = "the README's commands end to end, about 1.5 minutes"]
fn the_readme_runs_top_to_bottom() {
    let text = std::fs::read_to_string(root().join("README.md"))
        .unwrap_or_else(|e| panic!("README.md: {e}"));
    let dir = tempdir();
    let d = dir.path();
    let commands = fenced_commands(&text);
    assert!(commands.len() >= 9, "{commands:?}");
    for (line, args) in &commands {
        let words: Vec<&str> = args[1..].iter().map(String::as_str).collect();
        let out = softtouch(d, &words);
        let printed = ok(&out);
        eprintln!("README.md:{line}: softtouch {}: ok", words.join(" "));
        if words.first() == Some(&"status") {
            assert!(printed.contains("300"), "README.md:{line}: {printed}");
        }
    }
    for file in ["softtouch.db", "frame.png", "report.html"] {
        assert!(d.join(file).is_file(), "the README's commands leave {file}");
    }
}
