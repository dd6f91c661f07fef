//! Atomic file output and JSON helpers.
//!
//! Every file tubeloc writes goes to a temporary name in the same directory and is renamed into
//! place, so an interrupted run never leaves a half-written file. Paths that are not regular
//! files (devices, FIFOs, sockets, directories) are never renamed over: see [`write_atomic`].

use crate::error::CoreError;
use serde::{de::DeserializeOwned, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Most symbolic links followed when resolving an output path (Linux's own limit).
const MAX_SYMLINKS: usize = 40;

/// Where [`write_atomic`] puts the bytes, decided from what `path` is now.
#[derive(Debug, PartialEq, Eq)]
enum Target {
    /// A regular file (or nothing yet) at this path: temporary file, fsync, rename.
    Atomic(PathBuf),
    /// A character device, a FIFO, or any file reached through `/proc/` (e.g. `/dev/stdout`):
    /// opened and written in place.
    Direct(PathBuf),
}

/// Follows `path`'s symbolic links (at most [`MAX_SYMLINKS`]) and decides how to write it.
fn resolve_target(path: &Path) -> Result<Target, CoreError> {
    let mut p = path.to_path_buf();
    let mut via_special = false;
    for _ in 0..=MAX_SYMLINKS {
        // `/proc/<pid>/fd/<n>` (what `/dev/stdout` and `/dev/fd/<n>` lead to) names an open file
        // descriptor: renaming into /proc is impossible and replacing the file it leads to
        // would detach the descriptor from it.
        via_special |= p.starts_with("/proc");
        let meta = match std::fs::symlink_metadata(&p) {
            Ok(m) => m,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Target::Atomic(p)),
            Err(e) => return Err(CoreError::io(&p, e)),
        };
        let ft = meta.file_type();
        if ft.is_symlink() {
            if via_special {
                // `/dev/stdout -> /proc/self/fd/1 -> pipe:[…]`: the kernel, not the link text,
                // knows the file; open the path as given.
                return classify_special(path, &p);
            }
            let link = std::fs::read_link(&p).map_err(|e| CoreError::io(&p, e))?;
            p = match p.parent() {
                Some(dir) if link.is_relative() => dir.join(link),
                _ => link,
            };
            continue;
        }
        if ft.is_file() {
            return Ok(if via_special { Target::Direct(p) } else { Target::Atomic(p) });
        }
        return classify_special(path, &p);
    }
    Err(CoreError::invalid("output path", format!("{}: more than {MAX_SYMLINKS} levels of symbolic links", path.display())))
}

/// A path that is not a regular file: devices and FIFOs are written in place, the rest refused.
fn classify_special(given: &Path, p: &Path) -> Result<Target, CoreError> {
    let meta = std::fs::metadata(p).map_err(|e| CoreError::io(given, e))?;
    let ft = meta.file_type();
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if ft.is_socket() {
            return Err(CoreError::invalid("output path", format!("{} is a socket; refusing to write to it", given.display())));
        }
        if ft.is_block_device() {
            return Err(CoreError::invalid("output path", format!("{} is a block device; refusing to write to it", given.display())));
        }
    }
    if ft.is_dir() {
        return Err(CoreError::invalid("output path", format!("{} is a directory", given.display())));
    }
    Ok(Target::Direct(p.to_path_buf()))
}

/// Writes `bytes` to `path` atomically: temporary file in the same folder, fsync, rename.
/// Parent folders are created when missing.
///
/// What `path` is decides how it is written; a path that is not a regular file is never
/// replaced by one:
/// - missing or a regular file: temporary `.<name>.<pid>.tmp` beside it, fsync, rename over it
///   (an existing file's permissions are kept);
/// - a symbolic link: followed (up to 40 links, relative links against the link's folder), and
///   the file it leads to is written by these rules; the link itself is kept, so a link to a
///   regular file has that file replaced atomically in the file's own folder, and a dangling
///   link creates the file it names;
/// - a character device or a FIFO (`/dev/null`, a named pipe), or an existing file reached
///   through `/proc/` (`/dev/stdout`, `/dev/fd/N`): opened for writing and written in place,
///   without a temporary or a rename (a FIFO blocks until a reader opens it, as with a shell
///   redirect; a regular file reached as `/dev/stdout` is appended to, at the end of what
///   the shell's descriptor holds);
/// - a socket, a block device or a directory: refused with an error, nothing written.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), CoreError> {
    match resolve_target(path)? {
        Target::Direct(p) => write_direct(path, &p, bytes),
        Target::Atomic(p) => write_renamed(&p, bytes),
    }
}

/// Writes several files so that they appear together: every file goes to its temporary first,
/// and only when all are written are they renamed into place, one after the other, while an
/// exclusive lock (`flock`) is held on the folder of the first file. Two processes writing the
/// same group of files to one folder therefore leave all files of one of them, never a mix;
/// when any write fails, no file of the group is replaced and the temporaries are removed.
///
/// Each path follows the rules of [`write_atomic`]; files that are written in place (devices,
/// FIFOs) are written after the renames.
pub fn write_atomic_group(files: &[(&Path, &[u8])]) -> Result<(), CoreError> {
    let targets: Vec<Target> = files.iter().map(|(p, _)| resolve_target(p)).collect::<Result<_, _>>()?;
    let Some((first, _)) = files.first() else { return Ok(()) };
    let dir = match first.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(dir).map_err(|e| CoreError::io(dir, e))?;
    let _lock = FolderLock::exclusive(dir)?;
    let mut staged: Vec<(PathBuf, &Path)> = Vec::new();
    let mut failure = None;
    for (t, (_, bytes)) in targets.iter().zip(files) {
        if let Target::Atomic(p) = t {
            match stage(p, bytes) {
                Ok(tmp) => staged.push((tmp, p)),
                Err(e) => {
                    failure = Some(e);
                    break;
                }
            }
        }
    }
    if let Some(e) = failure {
        for (tmp, _) in &staged {
            let _ = std::fs::remove_file(tmp);
        }
        return Err(e);
    }
    for (i, (tmp, p)) in staged.iter().enumerate() {
        if let Err(e) = std::fs::rename(tmp, p) {
            for (t, _) in &staged[i..] {
                let _ = std::fs::remove_file(t);
            }
            return Err(CoreError::io(p, e));
        }
    }
    for (t, (given, bytes)) in targets.iter().zip(files) {
        if let Target::Direct(p) = t {
            write_direct(given, p, bytes)?;
        }
    }
    Ok(())
}

/// An exclusive `flock` on a folder, released when dropped (or when the process dies).
struct FolderLock {
    /// The open folder; closing it releases the lock.
    _file: std::fs::File,
}

impl FolderLock {
    fn exclusive(dir: &Path) -> Result<Self, CoreError> {
        let file = std::fs::File::open(dir).map_err(|e| CoreError::io(dir, e))?;
        #[cfg(unix)]
        {
            use std::os::fd::AsRawFd;
            // SAFETY: flock on a descriptor this function owns; it blocks until the lock is free.
            if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX) } != 0 {
                return Err(CoreError::io(dir, std::io::Error::last_os_error()));
            }
        }
        Ok(FolderLock { _file: file })
    }
}

/// Writes `bytes` into an existing non-regular file (device, FIFO, `/dev/stdout`) in place.
fn write_direct(given: &Path, p: &Path, bytes: &[u8]) -> Result<(), CoreError> {
    let regular = std::fs::metadata(p).map(|m| m.is_file()).unwrap_or(false);
    let mut opts = std::fs::OpenOptions::new();
    opts.write(true);
    if regular {
        opts.append(true);
    }
    let mut f = opts.open(p).map_err(|e| CoreError::io(given, e))?;
    f.write_all(bytes).and_then(|()| f.flush()).map_err(|e| CoreError::io(given, e))
}

/// The temporary-file-and-rename write of a regular file.
fn write_renamed(path: &Path, bytes: &[u8]) -> Result<(), CoreError> {
    let tmp = stage(path, bytes)?;
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        CoreError::io(path, e)
    })
}

/// Writes `bytes` to the temporary `.<name>.<pid>.tmp` beside `path` (fsynced, with the
/// permissions of the file it will replace); returns the temporary's path. Nothing is left
/// behind on failure.
fn stage(path: &Path, bytes: &[u8]) -> Result<PathBuf, CoreError> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(dir).map_err(|e| CoreError::io(dir, e))?;
    let name = path.file_name().ok_or_else(|| CoreError::invalid("output path", format!("{} has no file name", path.display())))?;
    let tmp = dir.join(format!(".{}.{}.tmp", name.to_string_lossy(), std::process::id()));
    let keep_permissions = std::fs::metadata(path).ok().filter(|m| m.is_file()).map(|m| m.permissions());
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        if let Some(perm) = keep_permissions {
            f.set_permissions(perm)?;
        }
        f.sync_all()
    })();
    match result {
        Ok(()) => Ok(tmp),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(CoreError::io(path, e))
        }
    }
}

/// Whether process `pid` is alive on this machine (`/proc/<pid>` exists). Where `/proc` is not
/// mounted every process counts as alive, so nothing is ever removed by mistake.
pub fn pid_alive(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    if !Path::new("/proc/self").exists() {
        return true;
    }
    Path::new("/proc").join(pid.to_string()).exists()
}

/// Removes the temporaries `<out>.tmp-<pid>` (folders or files beside `out`, as
/// `<out>.tmp-<pid>` names them) left by processes that are no longer alive, e.g. killed
/// `synth` or `bench` runs. Temporaries of live processes (this one included) are kept. Returns
/// the paths removed.
///
/// The pid is checked on this machine only: two machines writing the same `out` on a shared
/// filesystem would remove each other's temporaries (they would also overwrite each other's
/// output); give each job its own `out` (as `--shard` does).
pub fn remove_stale_temporaries(out: &Path) -> Result<Vec<PathBuf>, CoreError> {
    let Some(name) = out.file_name().map(|n| n.to_string_lossy().into_owned()) else { return Ok(Vec::new()) };
    let dir = match out.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let prefix = format!("{name}.tmp-");
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(CoreError::io(dir, e)),
    };
    let mut removed = Vec::new();
    for entry in entries.flatten() {
        let file_name = entry.file_name().to_string_lossy().into_owned();
        let Some(pid) = file_name.strip_prefix(&prefix).filter(|s| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit())).and_then(|s| s.parse::<u32>().ok()) else { continue };
        if pid_alive(pid) {
            continue;
        }
        let p = entry.path();
        let is_dir = entry.file_type().map(|t| t.is_dir()).unwrap_or(false);
        let r = if is_dir { std::fs::remove_dir_all(&p) } else { std::fs::remove_file(&p) };
        match r {
            Ok(()) => removed.push(p),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(CoreError::io(&p, e)),
        }
    }
    removed.sort();
    Ok(removed)
}

/// Serializes `value` as pretty JSON and writes it atomically to `path`.
pub fn write_json<T: Serialize + ?Sized>(path: &Path, value: &T) -> Result<(), CoreError> {
    let text = serde_json::to_vec_pretty(value).map_err(|e| CoreError::parse(path, format!("cannot serialize JSON: {e}")))?;
    write_atomic(path, &text)
}

/// Reads and parses a JSON file, with an error naming the file, line and column.
pub fn read_json<T: DeserializeOwned>(path: &Path) -> Result<T, CoreError> {
    let text = std::fs::read(path).map_err(|e| CoreError::io(path, e))?;
    parse_json(&text, path)
}

/// Parses JSON text (bytes of UTF-8) into `T`; `origin` names the source in errors ("invalid
/// JSON: " and serde's message with its line and column).
pub fn parse_json<T: DeserializeOwned>(text: &[u8], origin: &Path) -> Result<T, CoreError> {
    serde_json::from_slice(text).map_err(|e| CoreError::parse(origin, format!("invalid JSON: {e}")))
}

/// Parses TOML text into `T` and checks it with `validate`; `origin` names the source in
/// errors (the TOML error with its line and column, or the validation error).
pub fn parse_toml_checked<T: DeserializeOwned>(text: &str, origin: &Path, validate: impl FnOnce(&T) -> Result<(), CoreError>) -> Result<T, CoreError> {
    let value: T = toml::from_str(text).map_err(|e| CoreError::parse(origin, e.to_string().trim_end().to_string()))?;
    validate(&value).map_err(|e| CoreError::parse(origin, e.to_string()))?;
    Ok(value)
}

/// Reads a TOML file into `T` and checks it ([`parse_toml_checked`]).
pub fn read_toml_checked<T: DeserializeOwned>(path: &Path, validate: impl FnOnce(&T) -> Result<(), CoreError>) -> Result<T, CoreError> {
    let text = std::fs::read_to_string(path).map_err(|e| CoreError::io(path, e))?;
    parse_toml_checked(&text, path, validate)
}

/// Reads a settings file as `T`: TOML when its extension is `.toml` (any case), else JSON. A
/// parse error names the file and `what` (`invalid refine config: ...`) with the line and
/// column.
pub fn read_toml_or_json<T: DeserializeOwned>(path: &Path, what: &str) -> Result<T, CoreError> {
    let text = std::fs::read_to_string(path).map_err(|e| CoreError::io(path, e))?;
    if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("toml")) {
        toml::from_str(&text).map_err(|e| CoreError::parse(path, format!("invalid {what}: {}", e.to_string().trim_end())))
    } else {
        serde_json::from_str(&text).map_err(|e| CoreError::parse(path, format!("invalid {what}: {e}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_write_replaces_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sub/out.json");
        write_json(&p, &vec![1, 2, 3]).unwrap();
        write_json(&p, &vec![4]).unwrap();
        let back: Vec<i32> = read_json(&p).unwrap();
        assert_eq!(back, vec![4]);
        let names: Vec<_> = std::fs::read_dir(p.parent().unwrap()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 1, "temporary file left behind: {names:?}");
    }

    #[test]
    fn read_json_error_names_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.json");
        std::fs::write(&p, b"{ nope").unwrap();
        let err = read_json::<serde_json::Value>(&p).unwrap_err().to_string();
        assert!(err.contains("bad.json") && err.contains("line 1"), "{err}");
    }
}
