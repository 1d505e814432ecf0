//! The `softtouch` binary: parse arguments, set up logging, run, map the outcome to
//! an exit code (0 ok, 1 runtime failure, 2 bad input).

use clap::Parser as _;
use softtouch_collector::cli::{self, Cli};
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = Cli::parse(); // exits 2 on bad arguments, 0 on --help
    tracing_subscriber::fmt()
        .with_env_filter(
            // sqlx warns of "slow statements" when a streamed query (a dataset's
            // frames, read while they are preprocessed) stays open for over a second:
            // expected, not a fault, so its statement log is off unless RUST_LOG asks.
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| "warn,sqlx::query=error".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let runtime = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("error: cannot start the async runtime: {e}");
            return ExitCode::from(cli::EXIT_RUNTIME);
        }
    };
    let mut stdout = std::io::stdout().lock();
    match runtime.block_on(cli::run(cli, &mut stdout)) {
        Ok(()) => ExitCode::from(cli::EXIT_OK),
        Err(failure) => {
            eprintln!("error: {:#}", failure.error());
            ExitCode::from(failure.exit_code())
        }
    }
}
