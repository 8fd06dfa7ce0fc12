//! `mpmlab repair IN OUT`: a recording cut short (the process killed, the
//! machine down) made whole again.
//!
//! An `.rrd` file of rerun 0.36 is framed as: a 12-byte stream header
//! (`RRF2`, the writer's version, the encoding options), then messages,
//! each a 16-byte header (kind and length, little-endian u64s) and a
//! protobuf payload; a closing message of kind `End` carries the footer (a
//! manifest of every chunk, by store) and a fixed stream footer (`RRF2`,
//! `FOOT`) points back at it. The writer adds the footer when it closes;
//! `rerun rrd verify` and the viewer's random access need it. A killed
//! writer leaves the header and the messages written so far, the last one
//! possibly cut.
//!
//! Repair walks the frames, keeps every complete message that decodes
//! (rerun's own decoder) and writes them again with rerun's own encoder,
//! which rebuilds the footer. A recorded run flushes the file after every
//! step ([`crate::record::Recorder::sync`]), so the repaired recording holds
//! every step the run completed.

use rerun::external::re_build_info::CrateVersion;
use rerun::external::re_log_encoding::{
    Decodable, DecoderApp, Encoder, EncodingOptions, MessageHeader, MessageKind, StreamHeader,
};
use rerun::log::{Chunk, LogMsg};
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

/// Why a recording could not be repaired.
#[derive(Debug, thiserror::Error)]
pub enum RepairError {
    #[error("cannot read {path}: {message}")]
    Read { path: PathBuf, message: String },
    #[error("{path} is not a rerun recording: {message}")]
    NotARecording { path: PathBuf, message: String },
    #[error("{path} holds no complete message to keep")]
    Empty { path: PathBuf },
    #[error("cannot write {path}: {message}")]
    Write { path: PathBuf, message: String },
}

/// What a repair kept and dropped.
#[derive(Clone, Debug, PartialEq)]
pub struct Repaired {
    /// Messages written again (store infos, chunks, blueprint activations).
    pub messages: usize,
    /// Bytes of the input those messages (and the stream header) took.
    pub kept_bytes: u64,
    /// Bytes after them: an incomplete message, or a payload that does not
    /// decode and what follows it (0 for a complete recording).
    pub dropped_bytes: u64,
    /// Whether the input was already complete (it ended with rerun's
    /// footer); it is copied message by message all the same.
    pub complete: bool,
    /// The last step the recording's data reach (on the `step` timeline).
    pub last_step: Option<i64>,
    /// Why decoding stopped before the end of the complete frames, if it did.
    pub stopped: Option<String>,
}

impl std::fmt::Display for Repaired {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "kept {} messages ({} bytes)", self.messages, self.kept_bytes)?;
        if let Some(s) = self.last_step {
            write!(f, ", data up to step {s}")?;
        }
        if self.complete {
            write!(f, "; the recording was complete")?;
        } else if self.dropped_bytes == 0 {
            write!(f, "; the file ended between two messages, without rerun's footer")?;
        } else {
            write!(f, "; dropped {} bytes of an incomplete message", self.dropped_bytes)?;
        }
        if let Some(s) = &self.stopped {
            write!(f, " ({s})")?;
        }
        Ok(())
    }
}

/// The complete frames of a recording: where they end and whether a
/// closing `End` message was found. Only the frame headers are read.
struct Frames {
    version: CrateVersion,
    options: EncodingOptions,
    /// Bytes from the start to the end of the last complete message.
    end: u64,
    /// Where each complete message starts and ends (bytes), in order.
    spans: Vec<(u64, u64)>,
    complete: bool,
}

fn scan(path: &Path) -> Result<Frames, RepairError> {
    let read_err = |e: std::io::Error| RepairError::Read {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let not_rrd = |m: String| RepairError::NotARecording {
        path: path.to_path_buf(),
        message: m,
    };
    // Checked before opening: opening a FIFO blocks until a writer comes.
    let meta = std::fs::metadata(path).map_err(read_err)?;
    if !meta.is_file() {
        return Err(not_rrd(format!(
            "not a regular file ({})",
            if meta.is_dir() {
                "a folder"
            } else {
                "a device, FIFO or socket"
            }
        )));
    }
    let file = std::fs::File::open(path).map_err(read_err)?;
    let size = file.metadata().map_err(read_err)?.len();
    let mut r = BufReader::new(file);
    let mut head = [0u8; StreamHeader::ENCODED_SIZE_BYTES];
    r.read_exact(&mut head)
        .map_err(|_| not_rrd(format!("shorter than rerun's {}-byte stream header", head.len())))?;
    let (version, options) = StreamHeader::from_rrd_bytes(&head)
        .and_then(|h| h.to_version_and_options())
        .map_err(|e| not_rrd(e.to_string()))?;
    let mut end = head.len() as u64;
    let mut complete = false;
    let mut spans = Vec::new();
    let mut mh = [0u8; MessageHeader::ENCODED_SIZE_BYTES];
    while end + mh.len() as u64 <= size {
        r.read_exact(&mut mh).map_err(read_err)?;
        let Ok(h) = MessageHeader::from_rrd_bytes(&mh) else {
            break;
        };
        let frame_end = (end + mh.len() as u64).checked_add(h.len);
        match frame_end {
            Some(e) if e <= size => {
                if h.kind == MessageKind::End {
                    complete = true;
                    break;
                }
                spans.push((end, e));
                end = e;
                r.seek(SeekFrom::Start(end)).map_err(read_err)?;
            }
            _ => break,
        }
    }
    Ok(Frames {
        version,
        options,
        end,
        spans,
        complete,
    })
}

/// `f()`, or the panic's message when the decoder panics: rerun's arrow
/// decoder panics on some damaged payloads instead of returning an
/// error. The default hook's report is held back meanwhile (a repair
/// reports the damage itself).
fn guarded<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    std::panic::set_hook(hook);
    r.map_err(|p| {
        p.downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "the decoder failed".into())
    })
}

/// Repair `input` into `output`, written whole to `output`'s
/// `.partial` (locked: a second writer of `output` is refused; a stale
/// one is replaced only when `force`) and renamed into place. `output`
/// must not be `input`. A damaged message ends the repair there (its
/// byte range reported), whatever the decoder does with it.
pub fn repair(input: &Path, output: &Path, force: bool) -> Result<Repaired, RepairError> {
    let frames = scan(input)?;
    let read_err = |e: String| RepairError::Read {
        path: input.to_path_buf(),
        message: e,
    };
    let file = std::fs::File::open(input).map_err(|e| read_err(e.to_string()))?;
    let size = file.metadata().map_or(frames.end, |m| m.len());
    // The decoder sees the complete frames only: a cut message at the end
    // is not an error, it is what a repair drops.
    let mut decoder = DecoderApp::decode_lazy(BufReader::new(file.take(frames.end)));

    let write_err = |e: String| RepairError::Write {
        path: output.to_path_buf(),
        message: e,
    };
    let staged = crate::output::Staged::claim(output, force).map_err(write_err)?;
    let out = std::fs::OpenOptions::new()
        .write(true)
        .truncate(true)
        .open(staged.partial())
        .map_err(|e| write_err(e.to_string()));
    let written = out.and_then(|out| {
        let mut enc = Encoder::new_eager(frames.version, frames.options, BufWriter::new(out))
            .map_err(|e| write_err(e.to_string()))?;
        let step: rerun::TimelineName = "step".into();
        let (mut messages, mut last_step, mut stopped) = (0usize, None::<i64>, None);
        loop {
            let damaged = |why: String| match frames.spans.get(messages) {
                Some((a, b)) => format!("message {} (bytes {a}..{b}) does not decode: {why}", messages + 1),
                None => format!("message {} does not decode: {why}", messages + 1),
            };
            let msg = match guarded(|| decoder.next()) {
                Ok(None) => break,
                Ok(Some(Ok(m))) => m,
                Ok(Some(Err(e))) => {
                    stopped = Some(damaged(e.to_string()));
                    break;
                }
                Err(panic) => {
                    stopped = Some(damaged(panic));
                    break;
                }
            };
            if let LogMsg::ArrowMsg(store, arrow) = &msg {
                if store.is_recording() {
                    match guarded(|| {
                        Chunk::from_arrow_msg(arrow).map(|c| {
                            c.timelines()
                                .get(&step)
                                .and_then(|t| t.times_raw().iter().max().copied())
                        })
                    }) {
                        Ok(Ok(top)) => last_step = last_step.max(top),
                        Ok(Err(_)) => {}
                        Err(panic) => {
                            stopped = Some(damaged(panic));
                            break;
                        }
                    }
                }
            }
            match guarded(|| enc.append(&msg)) {
                Ok(r) => r.map_err(|e| write_err(e.to_string()))?,
                Err(panic) => {
                    stopped = Some(damaged(panic));
                    break;
                }
            };
            messages += 1;
        }
        if messages == 0 {
            return Err(RepairError::Empty {
                path: input.to_path_buf(),
            });
        }
        enc.finish().map_err(|e| write_err(e.to_string()))?;
        let w = enc.into_inner().map_err(|e| write_err(e.to_string()))?;
        let f = w.into_inner().map_err(|e| write_err(e.error().to_string()))?;
        f.sync_all().map_err(|e| write_err(e.to_string()))?;
        Ok((messages, last_step, stopped))
    });
    let (messages, last_step, stopped) = match written {
        Ok(w) => w,
        Err(e) => {
            staged.discard();
            return Err(e);
        }
    };
    staged.commit().map_err(write_err)?;
    // Stopped at a damaged message: kept up to the last that decoded.
    let kept = match (&stopped, messages.checked_sub(1).and_then(|m| frames.spans.get(m))) {
        (Some(_), Some(&(_, end))) => end,
        _ => frames.end,
    };
    Ok(Repaired {
        messages,
        kept_bytes: kept,
        dropped_bytes: if frames.complete && stopped.is_none() {
            0
        } else {
            size - kept
        },
        complete: frames.complete,
        last_step,
        stopped,
    })
}
