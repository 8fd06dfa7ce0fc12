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
        if let Some(s) = &self.stopped {
            return write!(
                f,
                "; stopped at a damaged message: dropped {} bytes from it on ({s})",
                self.dropped_bytes
            );
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

/// What a pass over the messages kept: how many, the last step their data
/// reach, and why it stopped early, if it did.
struct Pass {
    messages: usize,
    last_step: Option<i64>,
    stopped: Option<String>,
}

/// Decode the complete messages of `input` (its `frames`) one by one and
/// append each to `enc`, at most `limit` of them, calling `done(k)` after
/// the `k`-th. A message that does not decode (an error, or a panic of
/// the decoder, caught) ends the pass, named with its byte range; a write
/// error is one of `output` (what `enc` writes, for the report).
fn transcode<W: std::io::Write>(
    input: &Path,
    frames: &Frames,
    (enc, output): (&mut Encoder<W>, &Path),
    limit: Option<usize>,
    done: &mut dyn FnMut(usize),
) -> Result<Pass, RepairError> {
    let file = std::fs::File::open(input).map_err(|e| RepairError::Read {
        path: input.to_path_buf(),
        message: e.to_string(),
    })?;
    // The decoder sees the complete frames only: a cut message at the end
    // is not an error, it is what a repair drops.
    let mut decoder = DecoderApp::decode_lazy(BufReader::new(file.take(frames.end)));
    let step: rerun::TimelineName = "step".into();
    let mut pass = Pass {
        messages: 0,
        last_step: None,
        stopped: None,
    };
    let damaged = |k: usize, why: String| match frames.spans.get(k) {
        Some((a, b)) => format!("message {} (bytes {a}..{b}) does not decode: {why}", k + 1),
        None => format!("message {} does not decode: {why}", k + 1),
    };
    while limit.is_none_or(|l| pass.messages < l) {
        let k = pass.messages;
        let msg = match guarded(|| decoder.next()) {
            Ok(None) => break,
            Ok(Some(Ok(m))) => m,
            Ok(Some(Err(e))) => {
                pass.stopped = Some(damaged(k, e.to_string()));
                break;
            }
            Err(panic) => {
                pass.stopped = Some(damaged(k, panic));
                break;
            }
        };
        if let LogMsg::ArrowMsg(store, arrow) = &msg {
            if store.is_recording() {
                let top = guarded(|| {
                    Chunk::from_arrow_msg(arrow).map(|c| {
                        c.timelines()
                            .get(&step)
                            .and_then(|t| t.times_raw().iter().max().copied())
                    })
                });
                match top {
                    Ok(Ok(top)) => pass.last_step = pass.last_step.max(top),
                    Ok(Err(_)) => {}
                    Err(panic) => {
                        pass.stopped = Some(damaged(k, panic));
                        break;
                    }
                }
            }
        }
        match guarded(|| enc.append(&msg)) {
            Ok(r) => r.map_err(|e| RepairError::Write {
                path: output.to_path_buf(),
                message: e.to_string(),
            })?,
            Err(panic) => {
                pass.stopped = Some(damaged(k, panic));
                break;
            }
        };
        pass.messages += 1;
        done(pass.messages);
    }
    Ok(pass)
}

/// Decode every complete message of `input` as a repair would, writing
/// nothing, and report `ok K` on `out` after each: run in a process of
/// its own by `mpmlab repair`, so that a message on which the decoder
/// aborts the process (arrow asks for an allocation of petabytes on some
/// damaged lengths, which no guard can catch) is known by the last line.
pub fn probe(input: &Path, out: &mut dyn std::io::Write) -> Result<(), RepairError> {
    let frames = scan(input)?;
    let mut enc =
        Encoder::new_eager(frames.version, frames.options, std::io::sink()).map_err(|e| RepairError::Write {
            path: input.to_path_buf(),
            message: e.to_string(),
        })?;
    transcode(input, &frames, (&mut enc, Path::new("nowhere")), None, &mut |k| {
        let _ = writeln!(out, "ok {k}");
        let _ = out.flush();
    })?;
    Ok(())
}

/// The byte range of message `k` (1-based) of `input`, for a report.
pub fn message_bytes(input: &Path, k: usize) -> Option<(u64, u64)> {
    scan(input).ok()?.spans.get(k.checked_sub(1)?).copied()
}

/// Whether the first `limit` messages (all: `None`) make a recording
/// whose footer can be written: a damaged name can leave one chunk at odds
/// with the others of its entity, which only the footer's index finds.
/// `Err` with the reason when not.
fn closes(input: &Path, frames: &Frames, limit: Option<usize>) -> Result<usize, String> {
    let mut enc = Encoder::new_eager(frames.version, frames.options, std::io::sink()).map_err(|e| e.to_string())?;
    let pass =
        transcode(input, frames, (&mut enc, Path::new("nowhere")), limit, &mut |_| {}).map_err(|e| e.to_string())?;
    match guarded(|| enc.finish()) {
        Ok(Ok(())) => Ok(pass.messages),
        Ok(Err(e)) => Err(e.to_string()),
        Err(panic) => Err(panic),
    }
}

/// The most messages (at most `limit`) whose recording closes, and why
/// more do not when they do not ([`closes`]): the first try takes them
/// all, a bisection finds the longest prefix that closes otherwise.
fn closing_limit(input: &Path, frames: &Frames, limit: Option<(usize, String)>) -> Option<(usize, String)> {
    let first = closes(input, frames, limit.as_ref().map(|l| l.0));
    let (Err(why), n) = (first.clone(), limit.as_ref().map_or(usize::MAX, |l| l.0)) else {
        return limit;
    };
    // How many the pass took before it stopped: an upper bound.
    let mut enc = Encoder::new_eager(frames.version, frames.options, std::io::sink()).ok()?;
    let took = transcode(input, frames, (&mut enc, Path::new("nowhere")), Some(n), &mut |_| {})
        .ok()?
        .messages;
    drop(enc);
    let (mut lo, mut hi) = (0usize, took);
    // Invariant: `lo` messages close (none trivially), `hi` do not.
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        if closes(input, frames, Some(mid)).is_ok() {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let bytes = frames
        .spans
        .get(lo)
        .map_or(String::new(), |(a, b)| format!(" (bytes {a}..{b})"));
    Some((
        lo,
        format!(
            "message {}{bytes} does not decode: it leaves the recording's index inconsistent: {why}",
            lo + 1
        ),
    ))
}

/// Repair `input` into `output`, written whole to `output`'s
/// `.partial` (locked: a second writer of `output` is refused; a stale
/// one is replaced only when `force`) and renamed into place. `output`
/// must not be `input`. A damaged message ends the repair there (its
/// byte range reported), whatever the decoder does with it; `limit`
/// (with its reason) stops it before a message known to abort the
/// decoder ([`probe`]).
pub fn repair(
    input: &Path,
    output: &Path,
    force: bool,
    limit: Option<(usize, String)>,
) -> Result<Repaired, RepairError> {
    let frames = scan(input)?;
    let size = std::fs::metadata(input).map_or(frames.end, |m| m.len());
    let limit = closing_limit(input, &frames, limit);
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
        let mut pass = transcode(
            input,
            &frames,
            (&mut enc, output),
            limit.as_ref().map(|l| l.0),
            &mut |_| {},
        )?;
        if let Some((l, why)) = &limit {
            if pass.messages == *l && pass.stopped.is_none() {
                pass.stopped = Some(why.clone());
            }
        }
        if pass.messages == 0 {
            return Err(RepairError::Empty {
                path: input.to_path_buf(),
            });
        }
        enc.finish().map_err(|e| write_err(e.to_string()))?;
        let w = enc.into_inner().map_err(|e| write_err(e.to_string()))?;
        let f = w.into_inner().map_err(|e| write_err(e.error().to_string()))?;
        f.sync_all().map_err(|e| write_err(e.to_string()))?;
        Ok(pass)
    });
    let Pass {
        messages,
        last_step,
        stopped,
    } = match written {
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
