//! Helpers shared by the front end's integration tests (the `common`
//! module of `tests/frontend`): the engine's scene helpers, temporary
//! paths, the binary and recordings.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

#[path = "../../engine/tests/common/mod.rs"]
mod engine;
#[allow(unused_imports)]
pub use engine::*;

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
    event_texts(&read_chunks(path))
}

/// The texts of the `events` log of a recording's chunks.
pub fn event_texts(chunks: &[rerun::log::Chunk]) -> Vec<String> {
    let text = rerun::TextLog::descriptor_text().component;
    chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == "/events")
        .flat_map(|c| {
            c.iter_slices::<String>(text)
                .flat_map(|v| v.into_iter().map(|s| s.to_string()))
                .collect::<Vec<_>>()
        })
        .collect()
}

/// The step a failed run names in its message (`step N failed`): the
/// engine's failing step, which the outputs of a failed run must agree
/// with. Which step fails is the engine tests' business (for the plain
/// GIMP beam round-off picks it, `engine/tests/physics/finite.rs`).
pub fn failed_step(text: &str) -> usize {
    let (_, rest) = text
        .split_once("step ")
        .and_then(|(a, b)| b.contains(" failed").then_some((a, b)))
        .unwrap_or_else(|| panic!("no `step N failed` in: {text}"));
    let digits: String = rest.chars().take_while(|c| c.is_ascii_digit()).collect();
    let n: usize = digits.parse().unwrap_or_else(|_| panic!("no step number in: {text}"));
    assert!(
        text.contains(&format!("step {n} failed")),
        "the first `step N` is not the failure: {text}"
    );
    n
}
