//! Helpers shared by the integration tests (included with `mod common;`).
#![allow(dead_code)]

use mpmlab::scene::Scene;
use mpmlab::{Model, Simulation, StepReport};
use std::path::{Path, PathBuf};

/// Path of a shipped scene.
pub fn scene_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("scenarios")
        .join(format!("{name}.toml"))
}

/// Parse a shipped scene, let `edit` change it, build and return the simulation.
pub fn sim_with(name: &str, edit: impl FnOnce(&mut Scene)) -> Simulation {
    let path = scene_path(name);
    let text = std::fs::read_to_string(&path).unwrap();
    let mut scene = Scene::parse(&text, name).unwrap();
    edit(&mut scene);
    Simulation::new(Model::build(&scene, &text, name).unwrap())
}

/// Run every load step, panicking on failure.
pub fn run_all(sim: &mut Simulation) -> StepReport {
    let mut last = None;
    while !sim.finished() {
        last = Some(sim.step().unwrap_or_else(|f| panic!("{f}")));
    }
    last.unwrap()
}

pub fn error(r: &StepReport, name: &str) -> f64 {
    r.errors
        .iter()
        .find(|e| e.name == name)
        .unwrap_or_else(|| panic!("no error `{name}`"))
        .value
}

/// A unique temporary path (a file or a folder; not created here).
pub fn temp_path(stem: &str, ext: &str) -> TempPath {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    TempPath(std::env::temp_dir().join(format!("mpmlab-{stem}-{}-{nanos}.{ext}", std::process::id())))
}

/// A temporary path that is removed with what it holds when the test ends,
/// unless the test is failing: a failure leaves its files to look at.
pub struct TempPath(PathBuf);

impl std::ops::Deref for TempPath {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TempPath {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for TempPath {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

impl Drop for TempPath {
    fn drop(&mut self) {
        if std::thread::panicking() {
            return;
        }
        // Either a file or a folder, or nothing if the test removed it.
        let _ = std::fs::remove_file(&self.0);
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Every data chunk of the recording store in an `.rrd` file, decoded with
/// rerun's own decoder.
pub fn read_chunks(path: &std::path::Path) -> Vec<rerun::log::Chunk> {
    use rerun::external::re_log_encoding::DecoderApp;
    use rerun::log::{Chunk, LogMsg};
    let file = std::fs::File::open(path).unwrap();
    let decoder = DecoderApp::decode_eager(std::io::BufReader::new(file)).unwrap();
    decoder
        .filter_map(|msg| match msg.unwrap() {
            LogMsg::ArrowMsg(store, arrow) if store.is_recording() => Some(Chunk::from_arrow_msg(&arrow).unwrap()),
            _ => None,
        })
        .collect()
}

/// Run the `mpmlab` binary in the crate folder: exit code, stdout, stderr.
pub fn mpmlab(args: &[&str]) -> (i32, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_mpmlab"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Every text of a recording's `events` log, in file order.
pub fn events(path: &std::path::Path) -> Vec<String> {
    let text = rerun::TextLog::descriptor_text().component;
    read_chunks(path)
        .iter()
        .filter(|c| c.entity_path().to_string() == "/events")
        .flat_map(|c| {
            c.iter_slices::<String>(text)
                .flat_map(|v| v.into_iter().map(|s| s.to_string()))
                .collect::<Vec<_>>()
        })
        .collect()
}
