//! A pty pair from socat for the serial tests: the drivers' own, and (through
//! `#[path]`) the grasp loop's and the rig trials' over the Hand-E protocol.
#![allow(dead_code, unreachable_pub)]

/// Whether `socat` is on the PATH (the pty tests need it).
pub fn have_socat() -> bool {
    std::process::Command::new("socat")
        .arg("-V")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// A pty pair made by `socat -d -d pty,raw,echo=0 pty,raw,echo=0`: the child and the
/// two device paths. Dropping the guard kills socat.
#[derive(Debug)]
pub struct PtyPair {
    child: std::process::Child,
    pub a: String,
    pub b: String,
}

impl Drop for PtyPair {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Whether this runs under CI: the variable `CI` is set to anything but empty,
/// `0` or `false` (GitHub Actions, GitLab and most others set `CI=true`).
pub fn ci() -> bool {
    std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "0" && !v.eq_ignore_ascii_case("false"))
}

/// Start socat and read the two pty paths it reports; `None` when socat is missing on
/// a developer's machine. Under CI (`CI` set) a missing socat fails the test instead:
/// a skipped pty test there would pass without testing.
pub fn pty_pair() -> Option<PtyPair> {
    use std::io::BufRead;
    if !have_socat() {
        assert!(
            !ci(),
            "socat is not installed but CI is set: the pty tests must run in CI \
             (apt-get install socat)"
        );
        eprintln!("SKIPPED: socat is not installed (apt-get install socat); the pty test needs it");
        return None;
    }
    let mut child = std::process::Command::new("socat")
        .args(["-d", "-d", "pty,raw,echo=0", "pty,raw,echo=0"])
        .stderr(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("spawn socat");
    let stderr = child.stderr.take().expect("socat stderr");
    let mut lines = std::io::BufReader::new(stderr).lines();
    let mut paths = Vec::new();
    while paths.len() < 2 {
        let line = lines
            .next()
            .expect("socat reports its ptys")
            .expect("read socat stderr");
        if let Some(i) = line.find("PTY is ") {
            paths.push(line[i + 7..].trim().to_string());
        }
    }
    // Keep draining socat's log so it never blocks on a full pipe.
    std::thread::spawn(move || for _ in lines {});
    Some(PtyPair {
        child,
        a: paths[0].clone(),
        b: paths[1].clone(),
    })
}
