//! Output files written safely: a run's recording and step table are
//! written under a temporary name beside their target and renamed into
//! place when the run closes them, so a run that fails to start, or
//! stops on a write error, never truncates the file already there.
//!
//! | what | policy |
//! |---|---|
//! | while running | `NAME.partial`, locked (an exclusive advisory lock) so a second run writing `NAME` is refused |
//! | at the end | `NAME.partial` renamed to `NAME` (a symlink's target, not the link) |
//! | write error, crash | `NAME.partial` stays (a recording: `mpmlab repair NAME.partial NAME`) |
//! | a stale `NAME.partial` | refused, unless `--force` |
//! | `NAME` not of its kind | refused, unless `--force` (a regular file only) |
//! | the scene, a folder, a device, FIFO or socket | refused, `--force` or not |
//!
//! Two outputs of one run naming one file (through `./`, symlinks or hard
//! links) are refused by [`Identity`].

use std::fs::{File, OpenOptions, TryLockError};
use std::path::{Path, PathBuf};

/// A file's identity: its device and inode when it exists, else its
/// folder's canonical path and its name (what it will be once created).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Identity {
    Inode(u64, u64),
    Future(PathBuf),
}

impl Identity {
    /// The identity of `path` (following symlinks).
    pub fn of(path: &Path) -> Identity {
        use std::os::unix::fs::MetadataExt as _;
        if let Ok(m) = std::fs::metadata(path) {
            return Identity::Inode(m.dev(), m.ino());
        }
        let dir = match path.parent().filter(|d| !d.as_os_str().is_empty()) {
            Some(d) => d.to_path_buf(),
            None => PathBuf::from("."),
        };
        let dir = std::fs::canonicalize(&dir).unwrap_or(dir);
        Identity::Future(dir.join(path.file_name().unwrap_or_default()))
    }
}

/// Whether `a` and `b` are one file (or will be).
pub fn same_file(a: &Path, b: &Path) -> bool {
    Identity::of(a) == Identity::of(b)
}

/// A file-name stem made from a scene's name for default output names:
/// letters, digits, `-`, `_` and `.` kept (ASCII), anything else one `_`,
/// at most 48 bytes (a file system's names end at 255: a scene named with
/// a hundred emoji made `tui` fail), `scene` when nothing is left.
pub fn safe_stem(name: &str) -> String {
    let mut out = String::new();
    for c in name.chars() {
        let c = if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
            c
        } else {
            '_'
        };
        if !(c == '_' && out.ends_with('_')) {
            out.push(c);
        }
        if out.len() >= 48 {
            break;
        }
    }
    let out = out.trim_matches(|c| c == '_' || c == '.').to_string();
    if out.is_empty() {
        "scene".into()
    } else {
        out
    }
}

/// The entries of folder `dir` whose names are not among `ours`, sorted
/// (none when it cannot be read); and whether it holds anything at all.
pub fn foreign_entries(dir: &Path, ours: &[&str]) -> (Vec<String>, bool) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return (Vec::new(), false);
    };
    let names: Vec<String> = entries
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    let any = !names.is_empty();
    let mut foreign: Vec<String> = names.into_iter().filter(|n| !ours.contains(&n.as_str())).collect();
    foreign.sort();
    (foreign, any)
}

/// The first three of `names`, for a message.
pub fn some_of(names: &[String]) -> String {
    let more = names.len().saturating_sub(3);
    let head = names[..names.len().min(3)].join(", ");
    if more > 0 {
        format!("{head} and {more} more")
    } else {
        head
    }
}

/// `path` opened (created if missing, never truncated) and locked
/// exclusively: `Ok(None)` while another process holds it.
pub fn lock_file(path: &Path) -> Result<Option<File>, String> {
    let file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)
        .map_err(|e| {
            format!(
                "cannot create {}: {}",
                path.display(),
                mpmlab_engine::scene::io_reason(&e)
            )
        })?;
    match file.try_lock() {
        Ok(()) => Ok(Some(file)),
        Err(TryLockError::WouldBlock) => Ok(None),
        Err(TryLockError::Error(e)) => Err(format!("cannot lock {}: {e}", path.display())),
    }
}

/// `NAME.partial` of `path`.
pub fn partial_of(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".partial");
    PathBuf::from(s)
}

/// Why `path` may not be replaced at all (with `--force` or not): a
/// folder or a special file. `None` when it does not exist or is a
/// regular file (possibly through symlinks).
pub fn not_replaceable(path: &Path) -> Option<String> {
    use std::os::unix::fs::FileTypeExt as _;
    let m = std::fs::metadata(path).ok()?;
    let t = m.file_type();
    let what = if t.is_dir() {
        "a folder"
    } else if t.is_file() {
        return None;
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_block_device() || t.is_char_device() {
        "a device"
    } else {
        "not a regular file"
    };
    Some(format!(
        "{} is {what}; outputs replace regular files only (--force included)",
        path.display()
    ))
}

/// An output being written: the target, its locked temporary file, and
/// whether the temporary file is renamed into place or left at the end.
#[derive(Debug)]
pub struct Staged {
    /// Where the output goes (a symlink resolved to its target).
    target: PathBuf,
    partial: PathBuf,
    /// The temporary file, open and locked while the output is written.
    lock: File,
}

impl Staged {
    /// Claim `target` for writing: refused when it is a folder or a
    /// special file, or while another run writes it (its `.partial` is
    /// locked); a `.partial` left by an earlier run is refused unless
    /// `force`. The temporary file is created empty and locked; the
    /// writer opens it by [`Staged::partial`].
    pub fn claim(target: &Path, force: bool) -> Result<Staged, String> {
        if let Some(why) = not_replaceable(target) {
            return Err(why);
        }
        // A symlink's target is replaced, not the link.
        let target = std::fs::canonicalize(target).unwrap_or_else(|_| target.to_path_buf());
        let partial = partial_of(&target);
        if let Some(why) = not_replaceable(&partial) {
            return Err(why);
        }
        let Some(lock) = lock_file(&partial)? else {
            return Err(format!(
                "another run is writing {} (its {} is locked); wait for it or choose another path",
                target.display(),
                partial.display()
            ));
        };
        let stale = lock.metadata().map_or(0, |m| m.len());
        if stale > 0 && !force {
            return Err(format!(
                "{} ({stale} bytes) is left from a run that did not finish writing {}: \
                 recover it (a recording: mpmlab repair {} FILE) or remove it, or --force to replace it",
                partial.display(),
                target.display(),
                partial.display()
            ));
        }
        lock.set_len(0)
            .map_err(|e| format!("cannot truncate {}: {e}", partial.display()))?;
        Ok(Staged { target, partial, lock })
    }

    /// The final path (a symlink given resolved to its target).
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// The temporary file the output is written to.
    pub fn partial(&self) -> &Path {
        &self.partial
    }

    /// The output into place: its temporary file renamed to the target.
    pub fn commit(self) -> Result<(), String> {
        // The writer's data on disk before the name says it is whole.
        let _ = self.lock.sync_all();
        std::fs::rename(&self.partial, &self.target).map_err(|e| {
            format!(
                "cannot rename {} to {}: {} (the output is kept as {})",
                self.partial.display(),
                self.target.display(),
                mpmlab_engine::scene::io_reason(&e),
                self.partial.display()
            )
        })
    }

    /// Remove the temporary file (an output that was never written: the
    /// run did not start).
    pub fn discard(self) {
        let _ = std::fs::remove_file(&self.partial);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("mpmlab-output-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_second_claim_is_refused_while_the_first_holds_the_file() {
        let d = dir("lock");
        let t = d.join("run.rrd");
        let first = Staged::claim(&t, false).unwrap();
        let second = Staged::claim(&t, true).unwrap_err();
        assert!(second.contains("another run is writing"), "{second}");
        std::fs::write(first.partial(), b"RRF2 data").unwrap();
        first.commit().unwrap();
        assert_eq!(std::fs::read(&t).unwrap(), b"RRF2 data");
        assert!(!partial_of(&t).exists());
        // Free again once renamed.
        Staged::claim(&t, false).unwrap().discard();
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_stale_partial_is_kept_unless_forced() {
        let d = dir("stale");
        let t = d.join("run.csv");
        std::fs::write(partial_of(&t), b"step,1\n").unwrap();
        let e = Staged::claim(&t, false).unwrap_err();
        assert!(e.contains("left from a run"), "{e}");
        assert_eq!(std::fs::read(partial_of(&t)).unwrap(), b"step,1\n");
        let s = Staged::claim(&t, true).unwrap();
        assert_eq!(std::fs::metadata(s.partial()).unwrap().len(), 0);
        s.discard();
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn identity_sees_through_dots_symlinks_and_hard_links() {
        let d = dir("identity");
        let a = d.join("a.rrd");
        std::fs::write(&a, b"x").unwrap();
        std::os::unix::fs::symlink(&a, d.join("s.rrd")).unwrap();
        std::fs::hard_link(&a, d.join("h.rrd")).unwrap();
        assert!(same_file(&a, &d.join("./s.rrd")));
        assert!(same_file(&a, &d.join("h.rrd")));
        assert!(same_file(&d.join("new.csv"), &d.join(".").join("new.csv")));
        assert!(!same_file(&a, &d.join("new.csv")));
        // A claim through the symlink writes its target.
        let s = Staged::claim(&d.join("s.rrd"), false).unwrap();
        assert_eq!(s.target(), std::fs::canonicalize(&a).unwrap());
        s.discard();
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn scene_names_make_safe_short_stems() {
        assert_eq!(safe_stem("cook-membrane_2.h0.5"), "cook-membrane_2.h0.5");
        assert_eq!(safe_stem("a b/c\\d"), "a_b_c_d");
        assert_eq!(safe_stem("../../etc/passwd"), "etc_passwd");
        assert_eq!(safe_stem(&"\u{1F600}".repeat(100)), "scene");
        assert_eq!(safe_stem(&"x".repeat(300)).len(), 48);
        assert_eq!(safe_stem("Ωmega"), "mega");
    }

    #[test]
    fn folders_and_devices_are_never_replaced() {
        let d = dir("special");
        assert!(Staged::claim(&d, true).unwrap_err().contains("a folder"));
        assert!(Staged::claim(Path::new("/dev/null"), true)
            .unwrap_err()
            .contains("a device"));
        let _ = std::fs::remove_dir_all(&d);
    }
}
