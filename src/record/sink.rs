//! Where a recording's messages go: the file, encoded on rerun's sending
//! thread, with write errors kept and returned by every later flush.
//!
//! rerun's own file sink stops its writer thread at the first write error
//! (a full disk, a quota, EIO) but leaves the flush it was sent waiting
//! for an answer that never comes: the recorder's flush and the run
//! waiting for it hung for ever. This sink writes under a lock instead,
//! so a flush returns once the data is handed to the operating system, or
//! with the error that stopped the writing; the file keeps every message
//! written before it (`mpmlab repair` closes it).

use rerun::external::re_build_info::CrateVersion;
use rerun::external::re_log_encoding::{Encoder, EncodingOptions};
use rerun::log::LogMsg;
use rerun::sink::{LogSink, SinkFlushError};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};

/// The encoder and the first error, shared by the sink the stream owns and
/// the recorder, which closes the file ([`Shared::finish`]).
pub(super) struct Shared {
    path: PathBuf,
    state: Mutex<State>,
}

struct State {
    /// `None` once finished or failed.
    encoder: Option<Encoder<BufWriter<File>>>,
    error: Option<String>,
}

impl Shared {
    /// The file at `path` (created or truncated) with rerun's stream
    /// header.
    pub(super) fn create(path: &Path) -> Result<Arc<Shared>, String> {
        let file = File::create(path).map_err(|e| e.to_string())?;
        let encoder = Encoder::new_eager(
            CrateVersion::LOCAL,
            EncodingOptions::PROTOBUF_COMPRESSED,
            BufWriter::with_capacity(1 << 20, file),
        )
        .map_err(|e| e.to_string())?;
        Ok(Arc::new(Shared {
            path: path.to_path_buf(),
            state: Mutex::new(State {
                encoder: Some(encoder),
                error: None,
            }),
        }))
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Keep the first error and stop writing.
    fn fail(&self, s: &mut State, what: &str, e: impl std::fmt::Display) {
        s.error
            .get_or_insert_with(|| format!("{what} {}: {e}", self.path.display()));
        // Whatever the buffer still holds is dropped with it; the file
        // ends inside a message at worst, which a repair drops.
        if let Some(enc) = s.encoder.take() {
            drop(enc.into_inner());
        }
    }

    /// Write rerun's footer and hand the file to the operating system
    /// (synced to disk): the error if any write failed, now or before.
    pub(super) fn finish(&self) -> Result<(), String> {
        let mut s = self.lock();
        if let Some(e) = &s.error {
            return Err(e.clone());
        }
        let Some(mut enc) = s.encoder.take() else {
            return Ok(());
        };
        let closed = enc
            .finish()
            .map_err(|e| e.to_string())
            .and_then(|()| enc.into_inner().map_err(|e| e.to_string()))
            .and_then(|w| w.into_inner().map_err(|e| e.error().to_string()))
            .and_then(|f| f.sync_all().map_err(|e| e.to_string()));
        if let Err(e) = closed {
            s.error = Some(format!("cannot close {}: {e}", self.path.display()));
            return Err(s.error.clone().unwrap_or_default());
        }
        Ok(())
    }
}

/// The stream's sink: every message appended to the shared encoder.
pub(super) struct Sink(pub(super) Arc<Shared>);

impl LogSink for Sink {
    fn send(&self, msg: LogMsg) {
        let shared = &self.0;
        let mut s = shared.lock();
        if let Some(enc) = s.encoder.as_mut() {
            if let Err(e) = enc.append(&msg) {
                shared.fail(&mut s, "cannot write", e);
            }
        }
    }

    fn flush_blocking(&self, _timeout: std::time::Duration) -> Result<(), SinkFlushError> {
        let shared = &self.0;
        let mut s = shared.lock();
        if let Some(enc) = s.encoder.as_mut() {
            if let Err(e) = enc.flush_blocking() {
                shared.fail(&mut s, "cannot write", e);
            }
        }
        match &s.error {
            Some(e) => Err(SinkFlushError::failed(e.clone())),
            None => Ok(()),
        }
    }
}
