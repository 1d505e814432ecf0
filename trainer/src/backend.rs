//! Which burn backend runs the models. Model code has no backend parameter (burn
//! 0.22 carries the backend in the `Device`), so the choice is made here, at run time.
//!
//! - `flex` (default, always built): burn's pure-Rust CPU backend with SIMD kernels
//!   and rayon threads.
//! - `ndarray` (cargo feature `ndarray`, deprecated upstream): built only to compare
//!   against; see `trainer/README.md` for the measurements.
//!
//! `SOFTTOUCH_BACKEND=flex|ndarray` picks one; unset means `flex`. `SOFTTOUCH_CONV`
//! (see [`crate::kernels`]) is checked here too.

use burn::prelude::Device;

use crate::TrainError;

/// The environment variable that names the backend.
pub const ENV: &str = "SOFTTOUCH_BACKEND";

/// The device of the backend named by [`ENV`] (plain; training wraps it in autodiff).
pub fn device() -> Result<Device, TrainError> {
    // Training's kernels are chosen by their own variable; a mistyped value is said
    // here, before any work, rather than silently meaning the default.
    crate::kernels::parse_env(std::env::var(crate::kernels::ENV).ok().as_deref())
        .map_err(TrainError::Config)?;
    let name = std::env::var(ENV).unwrap_or_default();
    match name.as_str() {
        "" | "flex" => Ok(Device::flex()),
        #[cfg(feature = "ndarray")]
        "ndarray" => Ok(Device::ndarray()),
        other => Err(TrainError::Config(format!(
            "{ENV}={other}: this build has the backends {}",
            available().join(", ")
        ))),
    }
}

/// Backends this build can run.
pub fn available() -> Vec<&'static str> {
    let mut v = vec!["flex"];
    if cfg!(feature = "ndarray") {
        v.push("ndarray");
    }
    v
}
