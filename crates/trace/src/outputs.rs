//! The files one command writes, committed together: each is written to a temporary file
//! beside its destination, and all are renamed into place only after every one of them was
//! written. A command that fails part way (or is interrupted) leaves none of its outputs;
//! the temporary files are removed when the set is dropped uncommitted, and by
//! [`hytrace_foundry::npy::remove_temporaries`] when the command is interrupted.

use std::path::{Path, PathBuf};

use crate::error::{bail, Context};
use hytrace_foundry::npy::{temporary_beside, TrackedTemporary};
use tempfile::TempPath;

/// Outputs written but not yet in place.
#[derive(Default)]
pub struct OutputSet {
    /// Each output's temporary file, its destination, and its listing for an interrupt
    /// handler ([`hytrace_foundry::npy::remove_temporaries`]).
    staged: Vec<(TempPath, PathBuf, TrackedTemporary)>,
}

/// Checks before any work that every output can be written where asked: no path is an
/// existing directory and no two outputs share a path. `outputs` pairs each path with the
/// option that named it, for the message.
pub fn check_destinations(outputs: &[(&str, &Path)]) -> crate::Result<()> {
    for (i, (option, path)) in outputs.iter().enumerate() {
        if path.is_dir() {
            bail!("{option} {}: is a directory, not a file", path.display());
        }
        if let Some((other, _)) = outputs[..i].iter().find(|(_, p)| p == path) {
            bail!("{option} and {other} both name {}", path.display());
        }
    }
    Ok(())
}

impl OutputSet {
    /// An empty set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Writes one output: `write` is handed a temporary path in `dest`'s directory (created
    /// when missing) and writes the whole file there.
    pub fn stage(
        &mut self,
        dest: &Path,
        write: impl FnOnce(&Path) -> crate::Result<()>,
    ) -> crate::Result<()> {
        let tmp = self.reserve(dest)?;
        write(&tmp).with_context(|| format!("writing {}", dest.display()))
    }

    /// Adds an output to be written over time: the temporary path (in `dest`'s directory,
    /// created when missing) to write it at, moved onto `dest` by [`OutputSet::commit`].
    pub fn reserve(&mut self, dest: &Path) -> crate::Result<PathBuf> {
        let tmp = temporary_beside(dest)
            .with_context(|| format!("writing {}", dest.display()))?
            .into_temp_path();
        let tracked = TrackedTemporary::new(&tmp);
        // Temporary files are created private (0600); the output is an ordinary file.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&tmp, std::fs::Permissions::from_mode(0o644))
                .with_context(|| format!("writing {}", dest.display()))?;
        }
        let path = tmp.to_path_buf();
        self.staged.push((tmp, dest.to_path_buf(), tracked));
        Ok(path)
    }

    /// Moves every staged output into place.
    pub fn commit(self) -> crate::Result<()> {
        for (tmp, dest, _tracked) in self.staged {
            tmp.persist(&dest)
                .map_err(|e| e.error)
                .with_context(|| format!("writing {}", dest.display()))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nothing_lands_until_commit_and_a_failure_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.txt"), dir.path().join("sub/b.txt"));
        let mut set = OutputSet::new();
        set.stage(&a, |p| Ok(std::fs::write(p, "a")?)).unwrap();
        set.stage(&b, |p| Ok(std::fs::write(p, "b")?)).unwrap();
        assert!(!a.exists() && !b.exists());
        set.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&b).unwrap(), "b");
        // Ordinary files, not private like the temporary files they were written as.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&a).unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o644);
        }
        // A second output failing: the first is not left behind, nor any temporary file.
        let c = dir.path().join("c.txt");
        let mut set = OutputSet::new();
        set.stage(&c, |p| Ok(std::fs::write(p, "c")?)).unwrap();
        let failed = set.stage(&dir.path().join("d.txt"), |_| bail!("no"));
        assert!(failed.is_err());
        drop(set);
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        let mut names = names;
        names.sort();
        assert_eq!(names, ["a.txt", "sub"]);
    }

    #[test]
    fn directories_and_shared_paths_are_refused_by_option() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("hits.npy");
        let e = check_destinations(&[("--out", &file), ("--ids", dir.path())]).unwrap_err();
        assert!(e.to_string().starts_with("--ids ") && e.to_string().contains("directory"));
        let e = check_destinations(&[("--out", &file), ("--ids", &file)]).unwrap_err();
        assert!(e.to_string().contains("--ids and --out both name"), "{e}");
        check_destinations(&[("--out", &file)]).unwrap();
    }
}
