//! Checkpoints: the complete state of a run in full precision, to resume
//! it later (`mpmlab run --checkpoint DIR`, `--resume FILE`; the TUI's
//! `--resume`) and end bit for bit where the uninterrupted run ends.
//!
//! A checkpoint holds everything a step reads that the scene does not
//! give: the points (every array), the step, the accumulated work,
//! strain energy and ghost work (with the last ghost force), the active
//! cells, the ghost faces, the iteration count,
//! the implicit boundaries' offsets, the initial energy, and the settings
//! that may change between steps ([`Params`]). The caches a step rebuilds
//! (mass pattern, explicit buffers) are not kept.
//!
//! File layout: the magic line `mpmlab checkpoint\n`, the format version
//! (u32, little endian), then a CBOR record with the program's version,
//! the scene's name and a hash of its text, and the state. A checkpoint
//! is refused, with the reason, for another scene (or another text of
//! it), another program version or another format. Files are written to
//! a temporary name and renamed, so a run killed while writing leaves the
//! previous checkpoint whole.

use crate::simulation::{Params, Simulation};
use crate::state::State;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

const MAGIC: &[u8] = b"mpmlab checkpoint\n";
/// Bumped whenever the stored state changes shape.
const FORMAT: u32 = 1;

/// Why a checkpoint could not be written or used.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("cannot write checkpoint {path}: {message}")]
    Write { path: PathBuf, message: String },
    #[error("cannot read checkpoint {path}: {message}")]
    Read { path: PathBuf, message: String },
    #[error("checkpoint {path} does not fit this run: {message}")]
    Mismatch { path: PathBuf, message: String },
}

#[derive(Serialize, Deserialize)]
struct Record {
    version: String,
    scene: String,
    scene_hash: u64,
    params: Params,
    state: State,
}

/// FNV-1a hash of the scene text (stable across builds and platforms).
fn hash(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

/// The file name of the checkpoint after `step` in a checkpoint folder.
pub fn file_name(step: usize) -> String {
    format!("step-{step:06}.ckpt")
}

impl Simulation {
    /// Write the current state to `path` (`scene_text`: the scene file's
    /// text, whose hash the checkpoint keeps).
    pub fn save_checkpoint(&self, path: &Path, scene_text: &str) -> Result<(), CheckpointError> {
        let err = |message: String| CheckpointError::Write {
            path: path.to_path_buf(),
            message,
        };
        let record = Record {
            version: env!("CARGO_PKG_VERSION").to_string(),
            scene: self.model.name.clone(),
            scene_hash: hash(scene_text),
            params: self.params.clone(),
            state: self.state.clone(),
        };
        let mut bytes = MAGIC.to_vec();
        bytes.extend_from_slice(&FORMAT.to_le_bytes());
        ciborium::into_writer(&record, &mut bytes).map_err(|e| err(e.to_string()))?;
        let tmp = path.with_extension("ckpt.partial");
        std::fs::write(&tmp, &bytes).map_err(|e| err(crate::scene::io_reason(&e)))?;
        std::fs::rename(&tmp, path).map_err(|e| err(crate::scene::io_reason(&e)))
    }

    /// Continue from the checkpoint at `path`: the state and parameters
    /// it holds replace the current ones. `scene_text` must be the text
    /// the checkpoint was written with. Returns the step it was taken at.
    pub fn resume_from(&mut self, path: &Path, scene_text: &str) -> Result<usize, CheckpointError> {
        let read = |message: String| CheckpointError::Read {
            path: path.to_path_buf(),
            message,
        };
        let mismatch = |message: String| CheckpointError::Mismatch {
            path: path.to_path_buf(),
            message,
        };
        // A checkpoint larger than the run's memory budget could not be
        // loaded anyway; a FIFO or device would block or never end.
        use crate::scene::Refusal;
        let limit = self.model.max_memory;
        let bytes = crate::scene::read_regular_file(path, limit).map_err(|r| {
            read(match r {
                Refusal::Io(reason) => reason,
                Refusal::Directory => "it is a directory, not a checkpoint file".into(),
                Refusal::NotRegular(kind) => format!("it is not a regular file ({kind})"),
                Refusal::TooLarge(_) => format!("it is larger than the run's memory budget ({limit} bytes)"),
            })
        })?;
        let body = bytes
            .strip_prefix(MAGIC)
            .ok_or_else(|| read("not an mpmlab checkpoint (it does not start with `mpmlab checkpoint`)".into()))?;
        if body.len() < 4 {
            return Err(read("the file ends inside its header".into()));
        }
        let format = u32::from_le_bytes([body[0], body[1], body[2], body[3]]);
        if format != FORMAT {
            return Err(mismatch(format!(
                "it has checkpoint format {format}, this program reads format {FORMAT}"
            )));
        }
        let record: Record = ciborium::from_reader(&body[4..]).map_err(|e| read(format!("damaged: {e}")))?;
        let version = env!("CARGO_PKG_VERSION");
        if record.version != version {
            return Err(mismatch(format!(
                "it was written by mpmlab {}, this is mpmlab {version}: a resumed run would not end where the original does",
                record.version
            )));
        }
        if record.scene != self.model.name || record.scene_hash != hash(scene_text) {
            return Err(mismatch(format!(
                "it was written for scene `{}`{}; resume with the scene file it was written with",
                record.scene,
                if record.scene == self.model.name {
                    " with another text (the scene file changed since)"
                } else {
                    ""
                }
            )));
        }
        let s = &record.state;
        let n = s.points.len();
        let tracked = crate::state::tracked(self.model.analysis.kind);
        let consistent = s.points.fits(n, tracked)
            && n == self.state.points.len()
            && s.points.body.iter().all(|&b| b < self.model.bodies.len())
            && s.ibm_offsets.len() == self.model.ibm.len()
            && s.step <= self.load_steps()
            && s.active_cells
                .iter()
                .all(|&c| c < self.model.grid.nx * self.model.grid.ny);
        if !consistent {
            return Err(read(
                "damaged: its state does not fit the scene's points, bodies or grid".into(),
            ));
        }
        self.params = record.params;
        self.state = record.state;
        self.state.points.keep(tracked);
        Ok(self.state.step)
    }
}

/// Writes a checkpoint every `every` steps and after the last, as an
/// observer of the runner (`mpmlab run --checkpoint DIR`).
pub struct Checkpointer {
    dir: PathBuf,
    every: usize,
    scene_text: String,
    /// The step of the last checkpoint written.
    last: Option<usize>,
}

impl Checkpointer {
    /// Checkpoints into `dir` (created if missing).
    pub fn create(dir: &Path, every: usize, scene_text: &str) -> Result<Checkpointer, CheckpointError> {
        std::fs::create_dir_all(dir).map_err(|e| CheckpointError::Write {
            path: dir.to_path_buf(),
            message: crate::scene::io_reason(&e),
        })?;
        Ok(Checkpointer {
            dir: dir.to_path_buf(),
            every: every.max(1),
            scene_text: scene_text.to_string(),
            last: None,
        })
    }

    /// Write the state `sim` is in (unless already written); the path.
    pub fn write(&mut self, sim: &Simulation) -> Result<PathBuf, CheckpointError> {
        let path = self.dir.join(file_name(sim.step_index()));
        if self.last != Some(sim.step_index()) {
            sim.save_checkpoint(&path, &self.scene_text)?;
            self.last = Some(sim.step_index());
        }
        Ok(path)
    }

    /// The step of the last checkpoint written.
    pub fn last(&self) -> Option<usize> {
        self.last
    }
}

impl crate::runner::Observer for Checkpointer {
    fn stepped(&mut self, sim: &Simulation, r: &crate::simulation::StepReport) -> Option<String> {
        if r.step.is_multiple_of(self.every) || sim.finished() {
            return self.write(sim).err().map(|e| e.to_string());
        }
        None
    }
    /// The last good state, to go on from with other settings.
    fn failed(&mut self, sim: &Simulation, _f: &crate::simulation::StepFailure) -> Option<String> {
        self.write(sim).err().map(|e| e.to_string())
    }
}
