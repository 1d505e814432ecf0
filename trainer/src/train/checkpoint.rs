//! A training's checkpoint folder: the committed state, the data's fingerprint that a resume must match, reading, writing and discarding it.

use super::*;

/// The committed state of a checkpoint folder (`checkpoint.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct CheckpointState {
    pub(super) config: ModelConfig,
    pub(super) train: TrainConfig,
    pub(super) data_fingerprint: String,
    pub(super) norm: LabelNorm,
    pub(super) completed_epochs: usize,
    pub(super) best_epoch: usize,
    pub(super) best_score: f64,
    pub(super) model_file: String,
    pub(super) optimizer_file: String,
    pub(super) best_file: String,
    pub(super) history: Vec<EpochReport>,
    pub(super) seconds: f64,
    /// [`InitFrom::label`] of a fine-tuning (absent in older checkpoints: none).
    #[serde(default)]
    pub(super) init_from: Option<String>,
}

pub(super) const CHECKPOINT: &str = "checkpoint.json";

/// A short fingerprint of the training data (sizes and every label), so a resume on
/// different data is refused rather than silently mixed.
/// FNV-1a over byte slices, as 16 hex digits: stable across runs and platforms.
pub(super) fn fnv(parts: &[&[u8]]) -> String {
    let mut h = Fnv::default();
    for p in parts {
        h.feed(p);
    }
    format!("{:016x}", h.0)
}

pub(super) struct Fnv(pub(super) u64);

impl Default for Fnv {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv {
    pub(super) fn feed(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 ^= u64::from(*b);
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }
}

pub(super) fn fingerprint(splits: &Splits) -> String {
    // Over sizes and label bits.
    let mut h = Fnv::default();
    let mut feed = |bytes: &[u8]| h.feed(bytes);
    for split in [&splits.train, &splits.val, &splits.test] {
        feed(&(split.len() as u64).to_le_bytes());
        for e in split {
            for v in e.label {
                feed(&v.to_bits().to_le_bytes());
            }
            feed(&(e.image.len() as u64).to_le_bytes());
        }
    }
    format!("{:016x}", h.0)
}

pub(super) fn read_checkpoint(dir: &Path) -> Result<Option<CheckpointState>, TrainError> {
    let path = dir.join(CHECKPOINT);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(TrainError::io("read", &path, e)),
    };
    serde_json::from_str(&text)
        .map(Some)
        .map_err(|e| TrainError::Checkpoint(format!("{}: {e}", path.display())))
}

pub(super) fn write_checkpoint(
    dir: &Path,
    net: &Net,
    optimizer: &ModuleOptimizer,
    best: Option<&[u8]>,
    state: CheckpointState,
) -> Result<(), TrainError> {
    crate::write_atomic(&dir.join(&state.model_file), &record_bytes(net)?)?;
    let optim = optimizer
        .into_bytes()
        .map_err(|e| TrainError::Checkpoint(format!("encoding the optimiser state: {e}")))?;
    crate::write_atomic(&dir.join(&state.optimizer_file), &optim)?;
    let best_path = dir.join(&state.best_file);
    if !best_path.exists() {
        let bytes = match best {
            Some(b) => b.to_vec(),
            None => record_bytes(net)?,
        };
        crate::write_atomic(&best_path, &bytes)?;
    }
    let json = serde_json::to_vec_pretty(&state)
        .map_err(|e| TrainError::Checkpoint(format!("encoding the state: {e}")))?;
    crate::write_atomic(&dir.join(CHECKPOINT), &json)?;
    // Committed: files of other epochs are garbage now.
    let keep = [&state.model_file, &state.optimizer_file, &state.best_file];
    if let Ok(entries) = std::fs::read_dir(dir) {
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            let ours = name.starts_with("epoch-") || name.starts_with("best-");
            if ours && !keep.iter().any(|k| **k == name) {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
    Ok(())
}

/// Removes a checkpoint folder's files (for a deliberate restart).
pub fn discard_checkpoint(dir: &Path) -> Result<(), TrainError> {
    match std::fs::remove_dir_all(dir) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(TrainError::io("remove", dir, e)),
    }
}

/// Where checkpoints of a named training go under a root folder.
pub fn checkpoint_dir(root: &Path, name: &str) -> PathBuf {
    root.join(name)
}
