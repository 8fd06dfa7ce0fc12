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
//! (u32, little endian), the record's length in bytes and its checksum
//! (u64 each, little endian; FNV-1a, which any change of one byte
//! changes), then the record in CBOR: the program's version, the scene's
//! name and a hash of its text, and the state. A checkpoint is refused,
//! with the reason, for another scene (or another text of it), another
//! program version or another format, when it is truncated or its
//! checksum does not match, and when a value in it is one no run writes
//! ([`check`]: a negative volume, a `NaN` band width, ...). Files are
//! written to a temporary name and renamed, so a run killed while writing
//! leaves the previous checkpoint whole.

mod check;

use crate::simulation::{Params, Simulation};
use crate::state::State;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

const MAGIC: &[u8] = b"mpmlab checkpoint\n";
/// Bumped whenever the stored state or the framing changes shape (2:
/// length and checksum).
const FORMAT: u32 = 2;

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

/// FNV-1a hash of `bytes` (stable across builds and platforms). Each
/// step is invertible in the running hash, so two inputs of one length
/// that differ in one byte hash differently.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

/// The hash of the scene text a checkpoint keeps.
fn hash(text: &str) -> u64 {
    fnv1a(text.as_bytes())
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
        let mut body = Vec::new();
        ciborium::into_writer(&record, &mut body).map_err(|e| err(e.to_string()))?;
        let mut bytes = MAGIC.to_vec();
        bytes.extend_from_slice(&FORMAT.to_le_bytes());
        bytes.extend_from_slice(&(body.len() as u64).to_le_bytes());
        bytes.extend_from_slice(&fnv1a(&body).to_le_bytes());
        bytes.extend_from_slice(&body);
        let tmp = path.with_extension("ckpt.partial");
        // A folder, device, FIFO or socket is never replaced.
        for p in [path, tmp.as_path()] {
            if std::fs::symlink_metadata(p).is_ok_and(|m| !m.is_file())
                && !std::fs::metadata(p).is_ok_and(|m| m.is_file())
            {
                return Err(err(format!(
                    "{} is not a regular file; checkpoints replace regular files only",
                    p.display()
                )));
            }
        }
        if let Err(e) = std::fs::write(&tmp, &bytes) {
            // A full disk leaves no half checkpoint beside the whole ones.
            let _ = std::fs::remove_file(&tmp);
            return Err(err(crate::scene::io_reason(&e)));
        }
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
            return Err(read("damaged: the file ends inside its header (truncated)".into()));
        }
        let format = u32::from_le_bytes([body[0], body[1], body[2], body[3]]);
        if format != FORMAT {
            return Err(mismatch(format!(
                "it has checkpoint format {format}, this program reads format {FORMAT}"
            )));
        }
        let record = decode(&body[4..]).map_err(read)?;
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
        check::params(&record.params)
            .and_then(|()| check::state(s, &self.model))
            .map_err(|e| read(format!("damaged: {e}")))?;
        self.params = record.params;
        self.state = record.state;
        self.state.points.keep(tracked);
        Ok(self.state.step)
    }
}

/// The record after the format version: its length and checksum, then
/// the CBOR, each checked; the reason in words when it is damaged.
fn decode(framed: &[u8]) -> Result<Record, String> {
    if framed.len() < 16 {
        return Err("damaged: the file ends inside its header (truncated)".into());
    }
    let word = |i: usize| {
        let mut w = [0u8; 8];
        w.copy_from_slice(&framed[i..i + 8]);
        u64::from_le_bytes(w)
    };
    let (length, sum) = (word(0), word(8));
    let body = &framed[16..];
    if body.len() as u64 != length {
        return Err(format!(
            "damaged: its record should be {length} bytes and is {} ({})",
            body.len(),
            if (body.len() as u64) < length {
                "truncated"
            } else {
                "bytes added after it"
            }
        ));
    }
    if fnv1a(body) != sum {
        return Err("damaged: its checksum does not match its contents (the file changed after it was written)".into());
    }
    ciborium::from_reader(body).map_err(|e| {
        let why = match e {
            ciborium::de::Error::Io(_) => "it ends early".to_string(),
            ciborium::de::Error::Syntax(at) => format!("malformed at byte {at} of the record"),
            ciborium::de::Error::Semantic(at, msg) => match at {
                Some(at) => format!("{msg} at byte {at} of the record"),
                None => msg,
            },
            ciborium::de::Error::RecursionLimitExceeded => "nested too deeply".to_string(),
        };
        format!("damaged: the record cannot be read: {why}")
    })
}

/// Writes a checkpoint every `every` steps and after the last, as an
/// observer of the runner (`mpmlab run --checkpoint DIR`). The folder is
/// locked while the run writes it ([`LOCK`]).
pub struct Checkpointer {
    dir: PathBuf,
    every: usize,
    scene_text: String,
    /// The step of the last checkpoint written.
    last: Option<usize>,
    /// The folder's lock file, held (exclusively) while this lives.
    _lock: std::fs::File,
}

/// The lock file of a checkpoint folder: a second run writing the folder
/// is refused while the first holds it.
pub const LOCK: &str = ".mpmlab-checkpoints.lock";

/// Whether `name` in a checkpoint folder is one of this program's: a
/// checkpoint (`step-NNNNNN.ckpt`, checked to start as one), its
/// temporary file, or the folder's lock.
fn ours(dir: &Path, name: &str) -> bool {
    let step = |s: &str| s.len() == 6 && s.bytes().all(|b| b.is_ascii_digit());
    if name == LOCK {
        return true;
    }
    if let Some(n) = name.strip_prefix("step-").and_then(|n| n.strip_suffix(".ckpt.partial")) {
        return step(n);
    }
    let Some(n) = name.strip_prefix("step-").and_then(|n| n.strip_suffix(".ckpt")) else {
        return false;
    };
    let mut head = [0u8; MAGIC.len()];
    step(n)
        && std::fs::symlink_metadata(dir.join(name)).is_ok_and(|m| m.is_file())
        && std::fs::File::open(dir.join(name))
            .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut head))
            .is_ok_and(|()| head == *MAGIC)
}

impl Checkpointer {
    /// Checkpoints into `dir` (created if missing). A folder holding
    /// anything but this program's checkpoints is refused unless `force`
    /// (its other files are left alone either way), and so is a folder
    /// another run is writing.
    pub fn create(dir: &Path, every: usize, scene_text: &str, force: bool) -> Result<Checkpointer, CheckpointError> {
        let err = |message: String| CheckpointError::Write {
            path: dir.to_path_buf(),
            message,
        };
        if dir.exists() && !dir.is_dir() {
            return Err(err("it is not a folder".into()));
        }
        std::fs::create_dir_all(dir).map_err(|e| err(crate::scene::io_reason(&e)))?;
        let mut foreign = Vec::new();
        for entry in std::fs::read_dir(dir).map_err(|e| err(crate::scene::io_reason(&e)))? {
            let name = entry.map_err(|e| err(crate::scene::io_reason(&e)))?.file_name();
            let name = name.to_string_lossy();
            if !ours(dir, &name) {
                foreign.push(name.into_owned());
            }
        }
        if !foreign.is_empty() && !force {
            foreign.sort();
            let more = if foreign.len() > 3 {
                format!(" and {} more", foreign.len() - 3)
            } else {
                String::new()
            };
            return Err(err(format!(
                "the folder holds files that are not checkpoints of this program ({}{more}); \
                 choose another folder, or --force to write beside them",
                foreign[..foreign.len().min(3)].join(", ")
            )));
        }
        let lock = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(dir.join(LOCK))
            .map_err(|e| err(crate::scene::io_reason(&e)))?;
        match lock.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                return Err(err(
                    "another run is writing checkpoints to it; wait for it or choose another folder".into(),
                ))
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(err(format!("cannot lock it: {e}"))),
        }
        Ok(Checkpointer {
            dir: dir.to_path_buf(),
            every: every.max(1),
            scene_text: scene_text.to_string(),
            last: None,
            _lock: lock,
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

#[cfg(test)]
mod tests {
    use super::*;

    const SCENE: &str = r#"
[scene]
name = "ckpt-fuzz"
[grid]
origin = [0.0, 0.0]
size = [2.0, 2.0]
h = 0.25
[[material]]
name = "m"
E = 1.0e4
nu = 0.3
density = 10.0
[[body]]
name = "block"
material = "m"
points_per_cell = 2
region = { shape = "rectangle", min = [0.5, 0.5], max = [1.5, 1.0] }
[[dirichlet]]
kind = "fixed"
y = 0.5
[loads]
gravity = [0.0, -10.0]
[analysis]
kind = "quasi-static-finite"
load_steps = 3
"#;

    fn sim() -> Simulation {
        Simulation::from_scene_text(SCENE, "ckpt-fuzz.toml").expect("valid scene")
    }

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("mpmlab-ckpt-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// The bytes of the final checkpoint of a run resumed from `file`, or
    /// the refusal.
    fn resumed_end(file: &Path, end: &Path) -> Result<Vec<u8>, CheckpointError> {
        let mut s = sim();
        s.resume_from(file, SCENE)?;
        while !s.finished() {
            s.step().expect("the resumed run steps");
        }
        s.save_checkpoint(end, SCENE).unwrap();
        Ok(std::fs::read(end).unwrap())
    }

    /// Seeded damage to a checkpoint after step 1 of 3: 300 single-bit
    /// flips anywhere in the file and 60 truncations. Each damaged file is
    /// refused, or (never, with the checksum) resumes to the whole run's
    /// end to the bit: no damage may resume silently to another answer.
    #[test]
    fn damaged_checkpoints_are_refused_or_end_where_the_whole_run_ends() {
        let d = dir("fuzz");
        let mut whole = sim();
        whole.step().unwrap();
        let at1 = d.join("step-1.ckpt");
        whole.save_checkpoint(&at1, SCENE).unwrap();
        while !whole.finished() {
            whole.step().unwrap();
        }
        let end = d.join("end.ckpt");
        whole.save_checkpoint(&end, SCENE).unwrap();
        let expected = std::fs::read(&end).unwrap();
        let good = std::fs::read(&at1).unwrap();
        assert_eq!(
            resumed_end(&at1, &d.join("e.ckpt")).unwrap(),
            expected,
            "the undamaged checkpoint"
        );
        let mut rng = crate::linalg::XorShift::new(52);
        let damaged = d.join("damaged.ckpt");
        let (mut refused, mut same) = (0, 0);
        let mut check = |bytes: &[u8], what: &str| {
            std::fs::write(&damaged, bytes).unwrap();
            match resumed_end(&damaged, &d.join("e.ckpt")) {
                Err(e) => {
                    let e = e.to_string();
                    assert!(
                        !e.contains("Semantic(") && !e.contains("Syntax("),
                        "{what}: Debug text: {e}"
                    );
                    refused += 1;
                }
                Ok(end) => {
                    assert_eq!(end, expected, "{what}: resumed to another answer");
                    same += 1;
                }
            }
        };
        for _ in 0..300 {
            let bit = (rng.unit() * (8 * good.len()) as f64) as usize % (8 * good.len());
            let mut bytes = good.clone();
            bytes[bit / 8] ^= 1 << (bit % 8);
            check(&bytes, &format!("bit {bit} flipped"));
        }
        for _ in 0..60 {
            let len = (rng.unit() * good.len() as f64) as usize % good.len();
            check(&good[..len], &format!("cut to {len} bytes"));
        }
        assert_eq!((refused, same), (360, 0), "every damaged file refused");
        let _ = std::fs::remove_dir_all(&d);
    }

    /// Values edited by hand behind a valid checksum are refused by name.
    #[test]
    fn values_no_run_writes_are_refused_by_field() {
        let d = dir("values");
        let mut s = sim();
        s.step().unwrap();
        let file = d.join("ck.ckpt");
        s.save_checkpoint(&file, SCENE).unwrap();
        let bytes = std::fs::read(&file).unwrap();
        let header = MAGIC.len() + 4 + 16;
        let record: Record = ciborium::from_reader(&bytes[header..]).unwrap();
        type Edit = fn(&mut Record);
        let edits: [(&str, Edit); 5] = [
            ("`points.vol` of entry 3 is -1.0", |r| r.state.points.vol[3] = -1.0),
            ("`params.delta_over_h` is NaN", |r| r.params.delta_over_h = f64::NAN),
            ("`params.gamma_k` is -1000000000000000000000000000000", |r| {
                r.params.gamma_k = -1e30
            }),
            ("`points.x` of entry 0", |r| r.state.points.x[0] = [50.0, 0.7]),
            ("`points.def_grad` of entry 2", |r| {
                r.state.points.def_grad[2] = [1.0, 0.0, 0.0, -1.0]
            }),
        ];
        for (field, edit) in edits {
            let mut r = clone_record(&record);
            edit(&mut r);
            let mut body = Vec::new();
            ciborium::into_writer(&r, &mut body).unwrap();
            let mut out = bytes[..MAGIC.len() + 4].to_vec();
            out.extend_from_slice(&(body.len() as u64).to_le_bytes());
            out.extend_from_slice(&fnv1a(&body).to_le_bytes());
            out.extend_from_slice(&body);
            std::fs::write(&file, &out).unwrap();
            let e = sim().resume_from(&file, SCENE).unwrap_err().to_string();
            assert!(e.contains(field) && e.contains("damaged"), "{field}: {e}");
        }
        let _ = std::fs::remove_dir_all(&d);
    }

    /// A checkpoint folder with a user's files is refused unless forced,
    /// and the files are left alone; checkpoints of an earlier run are
    /// this program's; a folder another writer holds is refused.
    #[test]
    fn checkpoint_folders_hold_checkpoints_and_one_writer() {
        let d = dir("folders");
        let ck = d.join("ck");
        let mut s = sim();
        s.step().unwrap();
        {
            let mut c = Checkpointer::create(&ck, 1, SCENE, false).unwrap();
            c.write(&s).unwrap();
            // A second writer while the first holds the folder.
            let e = Checkpointer::create(&ck, 1, SCENE, true).err().unwrap().to_string();
            assert!(e.contains("another run is writing"), "{e}");
        }
        // An earlier run's checkpoints and lock are this program's.
        Checkpointer::create(&ck, 1, SCENE, false).unwrap();
        std::fs::write(ck.join("notes.txt"), b"mine").unwrap();
        std::fs::write(ck.join(file_name(7)), b"not a checkpoint").unwrap();
        let e = Checkpointer::create(&ck, 1, SCENE, false).err().unwrap().to_string();
        assert!(
            e.contains("notes.txt") && e.contains("step-000007.ckpt") && e.contains("--force"),
            "{e}"
        );
        let mut c = Checkpointer::create(&ck, 1, SCENE, true).unwrap();
        c.write(&s).unwrap();
        assert_eq!(std::fs::read(ck.join("notes.txt")).unwrap(), b"mine");
        // A file, not a folder.
        let e = Checkpointer::create(&ck.join("notes.txt"), 1, SCENE, true)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("not a folder"), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }

    fn clone_record(r: &Record) -> Record {
        Record {
            version: r.version.clone(),
            scene: r.scene.clone(),
            scene_hash: r.scene_hash,
            params: r.params.clone(),
            state: r.state.clone(),
        }
    }
}
