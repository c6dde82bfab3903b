//! Output files of the command line: never written over an input or over
//! each other, and written whole or not at all (each to a `NAME.partial`
//! sibling first, all renamed into place once every one is written); and
//! its messages on stderr ([`say`]).

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

/// Checks that no output is an input, a directory, another output or in a
/// directory that does not exist: before the work, not after it.
pub fn check(inputs: &[&Path], outputs: &[&Path]) -> Result<(), OutputError> {
    let inputs: Vec<PathBuf> = inputs.iter().filter_map(|p| std::fs::canonicalize(p).ok()).collect();
    let mut seen = Vec::new();
    for &out in outputs {
        if out.is_dir() {
            return Err(OutputError::Directory(out.to_path_buf()));
        }
        let dir = directory_of(out);
        if !dir.is_dir() {
            return Err(OutputError::NoDirectory(dir.to_path_buf()));
        }
        let resolved = resolve(out);
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
fn resolve(path: &Path) -> PathBuf {
    if let Ok(p) = std::fs::canonicalize(path) {
        return p;
    }
    match (std::fs::canonicalize(directory_of(path)), path.file_name()) {
        (Ok(d), Some(name)) => d.join(name),
        _ => path.to_path_buf(),
    }
}

/// Writes every `(path, bytes)`: all to `.partial` siblings, then each
/// renamed into place; on a failure the partial files are removed and no
/// output is touched.
pub fn write_all(files: &[(&Path, &[u8])]) -> Result<(), OutputError> {
    let partial = |p: &Path| {
        let mut name = p.as_os_str().to_owned();
        name.push(".partial");
        PathBuf::from(name)
    };
    let fail = |path: &Path, source| OutputError::Write { path: path.to_path_buf(), source };
    for (i, &(path, bytes)) in files.iter().enumerate() {
        if let Err(e) = std::fs::write(partial(path), bytes) {
            files[..=i].iter().for_each(|(p, _)| drop(std::fs::remove_file(partial(p))));
            return Err(fail(path, e));
        }
    }
    for &(path, _) in files {
        std::fs::rename(partial(path), path).map_err(|e| fail(path, e))?;
    }
    Ok(())
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

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("sylva-outputs-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
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
        assert!(!dir.join("a.tif.partial").exists(), "no partial file is left");
        write_all(&[(&a, b"new"), (&b, b"png")]).unwrap();
        assert_eq!((std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap()), (b"new".to_vec(), b"png".to_vec()));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
