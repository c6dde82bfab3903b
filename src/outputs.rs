//! Output files of the command line: never written over an input, over
//! each other, over anything but a regular file (a link is written
//! through) or over a file the user may not write; a replaced file's
//! permission bits kept (not its owner and group: the new file is its
//! writer's, with the writer's group); and written whole or not at all
//! (each to a new file of a unique name beside it first, all renamed into
//! place once every one is written); and its messages on stderr ([`say`]).

use std::path::{Path, PathBuf};

/// An output that would destroy an input or another output, or cannot be
/// written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// An output names a file the run reads.
    #[error("{0}: is also an input of this run; refusing to write over it")]
    IsInput(PathBuf),
    /// Two outputs name one file.
    #[error("{0}: is named as two outputs")]
    Twice(PathBuf),
    /// An output names an existing directory.
    #[error("{0}: is a directory")]
    Directory(PathBuf),
    /// An output names a device, a pipe or a socket.
    #[error("{0}: is not a regular file; refusing to replace it")]
    NotRegular(PathBuf),
    /// An output names a link to nothing (as `cp`, Sylva does not write
    /// through it).
    #[error("{0}: is a link to {1}, which does not exist; refusing to write through it")]
    DanglingLink(PathBuf, PathBuf),
    /// An output's directory is a file.
    #[error("{0}: is not a directory to write into")]
    NotDirectory(PathBuf),
    /// An output's directory does not exist.
    #[error("{0}: no such directory to write into")]
    NoDirectory(PathBuf),
    /// Writing or renaming failed.
    #[error("{path}: cannot write: {source}")]
    Write {
        /// The output asked for.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

/// Checks that no output is an input, a directory, something other than a
/// regular file, another output, or in a directory that does not exist or
/// cannot be written: before the work, not after it.
pub fn check(inputs: &[&Path], outputs: &[&Path]) -> Result<(), OutputError> {
    let inputs: Vec<PathBuf> = inputs.iter().filter_map(|p| std::fs::canonicalize(p).ok()).collect();
    let mut seen = Vec::new();
    for &out in outputs {
        destination(out)?;
        let dir = directory_of(out);
        if !dir.is_dir() {
            return Err(match dir.exists() {
                true => OutputError::NotDirectory(dir.to_path_buf()),
                false => OutputError::NoDirectory(dir.to_path_buf()),
            });
        }
        let resolved = resolve(out);
        // Writable now (a read-only file system fails here, not after the work).
        let (scratch, _) =
            scratch_beside(&resolved).map_err(|source| OutputError::Write { path: out.into(), source })?;
        let _ = std::fs::remove_file(scratch);
        if inputs.contains(&resolved) {
            return Err(OutputError::IsInput(out.to_path_buf()));
        }
        if seen.contains(&resolved) {
            return Err(OutputError::Twice(out.to_path_buf()));
        }
        seen.push(resolved);
    }
    Ok(())
}

/// Whether two paths name one file (the second need not exist).
pub fn same_file(a: &Path, b: &Path) -> bool {
    resolve(a) == resolve(b)
}

/// The directory a file is or would be in (`.` for a bare name).
fn directory_of(path: &Path) -> &Path {
    path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// The absolute path a file has or would have: links and `..` resolved
/// through its directory when the file does not exist yet.
pub(crate) fn resolve(path: &Path) -> PathBuf {
    if let Ok(p) = std::fs::canonicalize(path) {
        return p;
    }
    match (std::fs::canonicalize(directory_of(path)), path.file_name()) {
        (Ok(d), Some(name)) => d.join(name),
        _ => path.to_path_buf(),
    }
}

/// Where an output goes: the file it replaces and, when that file exists,
/// the permissions its replacement takes.
struct Destination {
    /// The path itself, or where its link leads.
    file: PathBuf,
    /// The replaced file's permission bits (`None`: a new file, made with
    /// the process's umask).
    permissions: Option<std::fs::Permissions>,
}

/// The file an output replaces: the path itself, or where its link leads
/// (so the link stays); an error for a directory, a device, a pipe, a
/// socket, a link to nothing, or a file this process may not write.
fn destination(path: &Path) -> Result<Destination, OutputError> {
    let meta = match std::fs::symlink_metadata(path) {
        // No such file yet (whether its directory is one is checked apart).
        Err(e) if matches!(e.kind(), std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory) => {
            return Ok(Destination { file: path.to_path_buf(), permissions: None });
        }
        Err(source) => return Err(OutputError::Write { path: path.to_path_buf(), source }),
        Ok(meta) => meta,
    };
    let target = match meta.is_symlink() {
        true => match std::fs::canonicalize(path) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                let to = std::fs::read_link(path).unwrap_or_default();
                return Err(OutputError::DanglingLink(path.into(), to));
            }
            resolved => resolved.map_err(|source| OutputError::Write { path: path.into(), source })?,
        },
        false => path.to_path_buf(),
    };
    match std::fs::metadata(&target) {
        Ok(m) if m.is_dir() => Err(OutputError::Directory(path.to_path_buf())),
        Ok(m) if m.is_file() => replaceable(path, target, &m),
        _ => Err(OutputError::NotRegular(path.to_path_buf())),
    }
}

/// The existing regular file `file` (output `path`, its metadata `meta`)
/// as a destination, if this process may write it: a rename needs only the
/// directory's permission, and would replace a file its user could not
/// write. The replacement keeps the file's permission bits, as `cp` does,
/// without set-id and sticky bits (the new file belongs to whoever writes
/// it, who must not gain them).
fn replaceable(path: &Path, file: PathBuf, meta: &std::fs::Metadata) -> Result<Destination, OutputError> {
    use std::os::unix::fs::PermissionsExt;
    // Opened for writing, not truncated: the kernel says whether this
    // process may write it (mode, ACLs, a read-only mount, root alike).
    let opened = std::fs::OpenOptions::new().write(true).open(&file);
    opened.map_err(|source| OutputError::Write { path: path.to_path_buf(), source })?;
    let permissions = std::fs::Permissions::from_mode(meta.permissions().mode() & 0o777);
    Ok(Destination { file, permissions: Some(permissions) })
}

/// A hidden name beside `path` that this process gives no other file:
/// `.NAME.PID.N.SUFFIX` ([`sibling_tagged`]).
pub fn sibling_name(path: &Path, suffix: &str) -> PathBuf {
    static COUNT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = COUNT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    sibling_tagged(path, &format!("{}.{n}", std::process::id()), suffix)
}

/// A hidden name beside `path`: `.NAME.TAG.SUFFIX`, NAME cut (at a
/// character boundary) so that a name near the file system's limit still
/// has a sibling.
pub fn sibling_tagged(path: &Path, tag: &str, suffix: &str) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default();
    let room = NAME_BYTES.saturating_sub(tag.len() + suffix.len() + 3);
    let cut = (0..=room.min(name.len())).rev().find(|&i| name.is_char_boundary(i)).unwrap_or(0);
    path.with_file_name(format!(".{}.{tag}.{suffix}", &name[..cut]))
}

/// The longest file name, in bytes, of the usual file systems (ext4, XFS,
/// NFS, APFS: `NAME_MAX`).
const NAME_BYTES: usize = 255;

/// A new file beside `path` that no other file has the name of (created
/// here, so nothing existing is written over), open for writing.
fn scratch_beside(path: &Path) -> std::io::Result<(PathBuf, std::fs::File)> {
    loop {
        let scratch = sibling_name(path, "partial");
        match std::fs::OpenOptions::new().write(true).create_new(true).open(&scratch) {
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            opened => return opened.map(|file| (scratch, file)),
        }
    }
}

/// Writes every `(path, bytes)`: all to new files beside them, then each
/// renamed into place; on a failure to write, the new files are removed and
/// no output is touched (a rename that fails, rare on one file system,
/// leaves those before it renamed).
pub fn write_all(files: &[(&Path, &[u8])]) -> Result<(), OutputError> {
    use std::io::Write;
    let mut written: Vec<(PathBuf, PathBuf)> = Vec::new();
    let mut write_one = |path: &Path, bytes: &[u8]| -> Result<(), OutputError> {
        let target = destination(path)?;
        let fail = |source| OutputError::Write { path: path.to_path_buf(), source };
        let (scratch, mut file) = scratch_beside(&target.file).map_err(fail)?;
        partial().push(scratch.clone());
        written.push((scratch, target.file));
        if let Some(permissions) = target.permissions {
            file.set_permissions(permissions).map_err(fail)?;
        }
        // In pieces: a signal that comes during a write(2) to a file waits
        // for it to end, and a second one sent meanwhile merges with it, so
        // one call for hundreds of MB left no room for the second Ctrl-C
        // that abandons the outputs.
        bytes.chunks(WRITE_CHUNK).try_for_each(|chunk| file.write_all(chunk)).map_err(fail)
    };
    let mut result = files.iter().try_for_each(|&(path, bytes)| write_one(path, bytes));
    let mut renamed = 0;
    if result.is_ok() {
        for ((scratch, target), &(path, _)) in written.iter().zip(files) {
            if let Err(source) = std::fs::rename(scratch, target) {
                result = Err(OutputError::Write { path: path.to_path_buf(), source });
                break;
            }
            renamed += 1;
        }
    }
    // Those renamed stay; the rest go with their scratch files.
    written[renamed..].iter().for_each(|(scratch, _)| drop(std::fs::remove_file(scratch)));
    partial().retain(|p| !written.iter().any(|(scratch, _)| scratch == p));
    result
}

/// Bytes per write(2) of [`write_all`]: milliseconds each.
const WRITE_CHUNK: usize = 4 << 20;

/// The new files [`write_all`] is writing, not yet renamed into place.
fn partial() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    static PARTIAL: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());
    PARTIAL.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Removes the new files a [`write_all`] still writes (a process that
/// abandons its outputs on a signal leaves none behind); the outputs
/// already renamed into place stay.
pub fn remove_partial() {
    remove_files(&mut partial());
}

/// Removes the files `paths` and forgets them.
fn remove_files(paths: &mut Vec<PathBuf>) {
    paths.drain(..).for_each(|path| drop(std::fs::remove_file(path)));
}

/// Writes a line to stderr. A stderr nobody reads any more (a pipe whose
/// reader left) is no reason to fail, nor to panic as `eprintln!` does.
pub fn say(text: std::fmt::Arguments) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr().lock(), "{text}");
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::FileTypeExt;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("sylva-outputs-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn abandoning_removes_the_new_files_being_written_and_no_output() {
        let dir = scratch("abandon");
        let (out, new) = (dir.join("out.tif"), dir.join(".out.tif.1.partial"));
        std::fs::write(&out, b"old").unwrap();
        std::fs::write(&new, b"half").unwrap();
        let mut paths = vec![new.clone()];
        remove_files(&mut paths);
        assert!(paths.is_empty() && !new.exists() && std::fs::read(&out).unwrap() == b"old");
        // A write registers its new files while it writes, and no more.
        write_all(&[(&out, b"new")]).unwrap();
        assert!(!partial().iter().any(|p| p.starts_with(&dir)), "{:?}", partial());
        assert_eq!(std::fs::read(&out).unwrap(), b"new");
    }

    #[test]
    fn an_output_may_not_be_an_input_a_directory_or_named_twice() {
        let dir = scratch("check");
        let input = dir.join("in.laz");
        std::fs::write(&input, b"x").unwrap();
        let (a, b) = (dir.join("a.tif"), dir.join("b.tif"));
        assert!(check(&[&input], &[&a, &b]).is_ok());
        let via_dots = dir.join("sub/../in.laz");
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        assert!(matches!(check(&[&input], &[&a, &via_dots]), Err(OutputError::IsInput(_))));
        assert!(matches!(check(&[], &[&a, &dir.join("./a.tif")]), Err(OutputError::Twice(_))));
        assert!(matches!(check(&[], &[&dir]), Err(OutputError::Directory(_))));
        let err = check(&[], &[&dir.join("no/such/c.png")]).unwrap_err().to_string();
        assert!(err.contains("no/such") && err.contains("no such directory"), "{err}");
        let err = check(&[], &[&input.join("c.png")]).unwrap_err().to_string();
        assert!(err.contains("in.laz: is not a directory"), "{err}");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 2, "no scratch file is left beside in.laz and sub/");
        assert!(same_file(&input, &via_dots) && !same_file(&a, &b));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn outputs_are_written_all_or_none() {
        let dir = scratch("write");
        let (a, b) = (dir.join("a.tif"), dir.join("b.png"));
        std::fs::write(&a, b"old").unwrap();
        let missing = dir.join("no/such/dir/c.png");
        let err = write_all(&[(&a, b"new"), (&missing, b"c")]).unwrap_err().to_string();
        assert!(err.contains("no/such/dir/c.png") && err.contains("cannot write"), "{err}");
        assert_eq!(std::fs::read(&a).unwrap(), b"old", "the earlier output is untouched");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1, "no partial file is left");
        write_all(&[(&a, b"new"), (&b, b"png")]).unwrap();
        assert_eq!((std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap()), (b"new".to_vec(), b"png".to_vec()));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_name_at_the_file_systems_limit_is_written() {
        // Regression: the scratch name, 20 bytes longer, was refused.
        let dir = scratch("long");
        let out = dir.join(format!("{}.tif", "é".repeat(125)));
        assert_eq!(out.file_name().unwrap().len(), 254);
        check(&[], &[&out]).unwrap();
        write_all(&[(&out, b"tif")]).unwrap();
        assert_eq!(std::fs::read(&out).unwrap(), b"tif");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_file_named_like_a_partial_output_is_left_alone() {
        // Regression: outputs went to `NAME.partial`, which destroyed a file
        // of that name, even the run's own configuration.
        let dir = scratch("partial");
        let (out, precious) = (dir.join("out.tif"), dir.join("out.tif.partial"));
        std::fs::write(&precious, b"precious").unwrap();
        write_all(&[(&out, b"tif")]).unwrap();
        assert_eq!(std::fs::read(&precious).unwrap(), b"precious");
        assert_eq!(std::fs::read(&out).unwrap(), b"tif");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_replaced_file_keeps_its_permissions_without_set_id_bits() {
        // Regression: the renamed new file had the umask's 0644 whatever the
        // replaced file's mode. (A file the user may not write is refused:
        // tests/integration/cli.rs, as another user.)
        use std::os::unix::fs::PermissionsExt;
        let dir = scratch("mode");
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o7777;
        let (private, shared, fresh) = (dir.join("private.tif"), dir.join("shared.tif"), dir.join("fresh.tif"));
        for (path, old) in [(&private, 0o600), (&shared, 0o4775)] {
            std::fs::write(path, b"old").unwrap();
            std::fs::set_permissions(path, std::fs::Permissions::from_mode(old)).unwrap();
        }
        check(&[], &[&private, &shared, &fresh]).unwrap();
        write_all(&[(&private, b"new"), (&shared, b"new"), (&fresh, b"new")]).unwrap();
        assert_eq!((mode(&private), mode(&shared)), (0o600, 0o775));
        let made = std::fs::File::create(dir.join("made")).unwrap().metadata().unwrap().permissions().mode();
        assert_eq!(mode(&fresh), made & 0o7777, "a new file is made as any other");
        assert_eq!(std::fs::read(&private).unwrap(), b"new");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn links_are_written_through_and_special_files_refused() {
        let dir = scratch("special");
        let (target, link) = (dir.join("real.tif"), dir.join("link.tif"));
        std::fs::write(&target, b"old").unwrap();
        std::os::unix::fs::symlink(&target, &link).unwrap();
        check(&[], &[&link]).unwrap();
        write_all(&[(&link, b"new")]).unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().is_symlink(), "the link stays a link");
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        let dangling = dir.join("dangling.tif");
        std::os::unix::fs::symlink(dir.join("nothing"), &dangling).unwrap();
        let err = check(&[], &[&dangling]).unwrap_err().to_string();
        assert!(err.ends_with("nothing, which does not exist; refusing to write through it"), "{err}");
        assert!(matches!(write_all(&[(&dangling, b"x")]), Err(OutputError::DanglingLink(..))));
        let null = Path::new("/dev/null");
        let err = check(&[], &[null]).unwrap_err().to_string();
        assert!(err.contains("not a regular file"), "{err}");
        assert!(matches!(write_all(&[(null, b"x")]), Err(OutputError::NotRegular(_))));
        assert!(std::fs::metadata(null).unwrap().file_type().is_char_device(), "/dev/null untouched");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
