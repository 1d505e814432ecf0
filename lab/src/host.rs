//! The machine a figure was taken on: CPU model and widest vector unit, named beside
//! every speed figure (hosts here differ twofold in speed).

/// A host as a figure names it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Host {
    /// `model name` of /proc/cpuinfo, or the architecture where there is none.
    pub cpu: String,
    /// `AVX-512`, `AVX2` or the architecture's own (e.g. `aarch64`).
    pub simd: &'static str,
    /// Logical cores.
    pub cores: usize,
}

impl Host {
    /// This machine.
    #[must_use]
    pub fn this() -> Self {
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|text| model_name(&text))
            .unwrap_or_else(|| std::env::consts::ARCH.to_owned());
        Self {
            cpu,
            simd: simd(),
            cores: std::thread::available_parallelism().map_or(1, std::num::NonZero::get),
        }
    }

    /// `Intel(R) Xeon(R) Processor, AVX-512, 2 cores`.
    #[must_use]
    pub fn line(&self) -> String {
        format!("{}, {}, {} cores", self.cpu, self.simd, self.cores)
    }
}

/// The first `model name` line's value.
fn model_name(cpuinfo: &str) -> Option<String> {
    cpuinfo
        .lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split_once(':'))
        .map(|(_, v)| v.trim().to_owned())
        .filter(|v| !v.is_empty())
}

#[cfg(target_arch = "x86_64")]
fn simd() -> &'static str {
    if std::arch::is_x86_feature_detected!("avx512f") {
        "AVX-512"
    } else if std::arch::is_x86_feature_detected!("avx2") {
        "AVX2"
    } else {
        "x86-64 without AVX2"
    }
}

#[cfg(not(target_arch = "x86_64"))]
fn simd() -> &'static str {
    std::env::consts::ARCH
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_model_name_is_read_or_left_out() {
        let text = "processor\t: 0\nmodel name\t: Intel(R) Xeon(R) Processor\nflags\t: avx2\n";
        assert_eq!(
            model_name(text).as_deref(),
            Some("Intel(R) Xeon(R) Processor")
        );
        assert_eq!(model_name(""), None);
        assert_eq!(model_name("model name\t:   \n"), None);
        let host = Host::this();
        assert!(!host.cpu.is_empty() && host.cores >= 1, "{host:?}");
    }
}
