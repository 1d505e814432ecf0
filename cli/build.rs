// The git commit the binary is built from, for the provenance of stored results
// (`SOFTTOUCH_COMMIT`; unset outside a git checkout). Reruns when HEAD moves.
use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_owned())
        .filter(|s| !s.is_empty())
}

fn main() {
    println!("cargo:rerun-if-env-changed=SOFTTOUCH_COMMIT");
    if let Some(dir) = git(&["rev-parse", "--absolute-git-dir"]) {
        println!("cargo:rerun-if-changed={dir}/HEAD");
        println!("cargo:rerun-if-changed={dir}/packed-refs");
        if let Some(reference) = git(&["symbolic-ref", "-q", "HEAD"]) {
            println!("cargo:rerun-if-changed={dir}/{reference}");
        }
    }
    if std::env::var_os("SOFTTOUCH_COMMIT").is_none()
        && let Some(commit) = git(&["rev-parse", "HEAD"])
    {
        println!("cargo:rustc-env=SOFTTOUCH_COMMIT={commit}");
    }
}
