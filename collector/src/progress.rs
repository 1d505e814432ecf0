//! Progress for long work: the one progress-bar style (stderr, hidden when stderr is not
//! a terminal) and the training observer that prints a line per epoch with its ETA.
//!
//! Dataset export and import, the training verbs, sweeps and benchmarks all report
//! through here, so every long job looks the same to an operator.

use softtouch_trainer::train::{EpochReport, Observer};
use std::io::Write;
use std::time::Instant;

/// A progress bar on stderr, hidden when stderr is not a terminal.
pub fn progress_bar(len: u64, enabled: bool, what: &str) -> indicatif::ProgressBar {
    use std::io::IsTerminal as _;
    if !enabled || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    if let Ok(style) = indicatif::ProgressStyle::with_template(&format!(
        "{what} {{bar:40}} {{pos}}/{{len}} {{per_sec}} eta {{eta}}"
    )) {
        bar.set_style(style);
    }
    bar
}

/// Prints one line per epoch (loss, validation R², throughput, ETA) and drives a
/// progress bar over the batches.
pub struct TrainProgress<'a> {
    out: &'a mut dyn Write,
    bar: indicatif::ProgressBar,
    epochs: usize,
    started: Instant,
    first_epoch: usize,
    show_bar: bool,
}

impl std::fmt::Debug for TrainProgress<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TrainProgress")
            .field("epochs", &self.epochs)
            .field("first_epoch", &self.first_epoch)
            .finish_non_exhaustive()
    }
}

impl<'a> TrainProgress<'a> {
    /// Report to `out` over up to `epochs` epochs.
    pub fn new(out: &'a mut dyn Write, epochs: usize, show_bar: bool) -> Self {
        Self {
            out,
            bar: indicatif::ProgressBar::hidden(),
            epochs,
            started: Instant::now(),
            first_epoch: 0,
            show_bar,
        }
    }
}

// Lines are best effort: a closed output must not stop a training that is storing its
// checkpoints, so write errors are ignored here (the verb's own writes report them).
impl Observer for TrainProgress<'_> {
    fn resumed(&mut self, completed: usize) {
        self.first_epoch = completed;
        writeln!(
            self.out,
            "resuming from the checkpoint after epoch {completed}"
        )
        .ok();
    }
    fn batch(&mut self, epoch: usize, step: usize, steps: usize) {
        if step == 1 {
            self.bar.finish_and_clear();
            self.bar = progress_bar(steps as u64, self.show_bar, &format!("epoch {epoch}"));
        }
        self.bar.set_position(step as u64);
    }
    fn epoch(&mut self, r: &EpochReport) {
        self.bar.finish_and_clear();
        let done = r.epoch.saturating_sub(self.first_epoch).max(1);
        let per_epoch = self.started.elapsed().as_secs_f64() / done as f64;
        let eta = per_epoch * self.epochs.saturating_sub(r.epoch) as f64;
        let opt = |v: Option<f64>| v.map_or_else(|| "–".to_owned(), |v| format!("{v:.4}"));
        writeln!(
            self.out,
            "epoch {:>3}/{}  loss {:.4}  val R² mean {} min {}  val image MSE {}  {:.0} img/s  {:.1} s  eta ≤ {:.0} s{}",
            r.epoch,
            self.epochs,
            r.train_loss,
            opt(r.val_r2_mean),
            opt(r.val_r2_min),
            r.val_image_mse
                .map_or_else(|| "–".to_owned(), |v| format!("{v:.2e}")),
            r.train_images_per_s,
            r.seconds,
            eta,
            if r.best { "  (best)" } else { "" }
        )
        .ok();
    }
}

struct BarProgress {
    bar: indicatif::ProgressBar,
}

impl crate::collect::Progress for BarProgress {
    fn sample_done(&mut self, _index: u64, c: &crate::collect::Counters) {
        self.bar.inc(1);
        self.bar.set_message(format!(
            "ok {} rejected {} retries {}",
            c.ok, c.rejected, c.retries
        ));
    }
    fn note(&mut self, message: &str) {
        self.bar.println(message);
    }
}

/// Log lines for a log file or CI: at most one every 10 s, and the last.
struct LineProgress {
    started: Instant,
    last: Instant,
    done: u64,
    total: u64,
}

impl crate::collect::Progress for LineProgress {
    fn sample_done(&mut self, index: u64, c: &crate::collect::Counters) {
        self.done += 1;
        let now = Instant::now();
        if now.duration_since(self.last).as_secs() >= 10 || self.done == self.total {
            self.last = now;
            let secs = now.duration_since(self.started).as_secs_f64().max(1e-9);
            let rate = self.done as f64 / secs;
            let eta = (self.total - self.done) as f64 / rate.max(1e-9);
            eprintln!(
                "sample {index}: {}/{} done ({:.1}/s, ETA {:.0} s), ok {} rejected {} retries {}",
                self.done, self.total, rate, eta, c.ok, c.rejected, c.retries
            );
        }
    }
    fn note(&mut self, message: &str) {
        eprintln!("{message}");
    }
}

/// A collection's progress: a bar on a terminal, log lines otherwise (at most one
/// every 10 s, and the last, with the rate and ETA).
#[must_use]
pub fn collection_progress(total: u64) -> Box<dyn crate::collect::Progress> {
    if std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        let bar = indicatif::ProgressBar::new(total);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{elapsed_precise} [{bar:40}] {pos}/{len} samples {per_sec} ETA {eta} {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        Box::new(BarProgress { bar })
    } else {
        let now = Instant::now();
        Box::new(LineProgress {
            started: now,
            last: now,
            done: 0,
            total,
        })
    }
}
