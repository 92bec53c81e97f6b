//! The README's quickstarts, run as written: every fenced `sh` block under its
//! `## Quickstart` and `## Detector pictures` headings runs in `bash -euo pipefail` with
//! this build's `hytrace` first on `PATH`, in a fresh directory that holds only the
//! repository's `scenes/` and `tests/` (what a clone has), with the shared GDML corpus
//! beside it as `../shared` (where the README says a clone finds it). A block fails the test when any command exits non-zero or when an
//! output it names (`-o`, `--out`, `--ids`, `--rays`, `--transmittance`, `--history=`) is
//! missing or empty afterwards.

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The fenced `sh` blocks of the README section headed `heading` (`## ...`).
fn section_blocks(readme: &str, heading: &str) -> Vec<String> {
    let mut in_section = false;
    let mut block: Option<String> = None;
    let mut blocks = Vec::new();
    for line in readme.lines() {
        if let Some(b) = block.as_mut() {
            if line.trim_start().starts_with("```") {
                blocks.push(block.take().unwrap());
            } else {
                b.push_str(line);
                b.push('\n');
            }
            continue;
        }
        if line.starts_with("## ") {
            in_section = line.trim() == heading;
        } else if in_section && line.trim() == "```sh" {
            block = Some(String::new());
        }
    }
    assert!(
        block.is_none(),
        "unterminated code block in the section {heading}"
    );
    blocks
}

/// The output paths a block's commands name.
fn outputs(block: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in block.lines() {
        let words: Vec<&str> = line.split_whitespace().collect();
        for (i, w) in words.iter().enumerate() {
            if let Some(path) = w.strip_prefix("--history=") {
                out.push(path.to_string());
            } else if matches!(*w, "-o" | "--out" | "--ids" | "--rays" | "--transmittance") {
                if let Some(path) = words.get(i + 1) {
                    out.push(path.to_string());
                }
            }
        }
    }
    out
}

fn non_empty(path: &Path) -> bool {
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => std::fs::read_dir(path).is_ok_and(|mut d| d.next().is_some()),
        Ok(m) => m.len() > 0,
        Err(_) => false,
    }
}

#[test]
fn the_block_parser_finds_commands_and_outputs() {
    let readme = "# x\n```sh\nnot this\n```\n## Quickstart\ntext\n```sh\nhytrace a -o out/a.png\nhytrace b --history=out/h.npy --out out/b.npy\n```\n```python\nno\n```\n## Next\n```sh\nnor this\n```\n";
    let blocks = section_blocks(readme, "## Quickstart");
    assert_eq!(
        blocks,
        ["hytrace a -o out/a.png\nhytrace b --history=out/h.npy --out out/b.npy\n"]
    );
    assert_eq!(outputs(&blocks[0]), ["out/a.png", "out/h.npy", "out/b.npy"]);
}

#[cfg(unix)]
#[test]
fn readme_quickstarts_run_as_written() {
    let root = repo_root();
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let mut blocks = section_blocks(&readme, "## Quickstart");
    assert!(
        blocks.len() >= 4,
        "the README's Quickstart section should hold at least 4 sh blocks, found {}",
        blocks.len()
    );
    let pictures = section_blocks(&readme, "## Detector pictures");
    assert!(!pictures.is_empty(), "the README shows no picture commands");
    blocks.extend(pictures);

    // A directory with what a clone has, the shared corpus beside it; outputs go to the
    // clone's `out/` (and `docs/pictures/`).
    let top = tempfile::tempdir().unwrap();
    let clone = top.path().join("clone");
    std::fs::create_dir(&clone).unwrap();
    let shared = root.join("../shared");
    assert!(
        shared.join("gdml").is_dir(),
        "the shared corpus {} is missing",
        shared.display()
    );
    std::os::unix::fs::symlink(shared.canonicalize().unwrap(), top.path().join("shared")).unwrap();
    for dir in ["scenes", "tests"] {
        std::os::unix::fs::symlink(root.join(dir).canonicalize().unwrap(), clone.join(dir))
            .unwrap();
    }
    let bin = PathBuf::from(env!("CARGO_BIN_EXE_hytrace"));
    let path = std::env::join_paths(std::iter::once(bin.parent().unwrap().to_path_buf()).chain(
        std::env::split_paths(&std::env::var_os("PATH").unwrap_or_default()),
    ))
    .unwrap();

    for (i, block) in blocks.iter().enumerate() {
        assert!(
            block
                .lines()
                .any(|l| l.trim_start().starts_with("hytrace ")),
            "quickstart block {} runs no hytrace command:\n{block}",
            i + 1
        );
        let o = Command::new("bash")
            .args(["-euo", "pipefail", "-c", block])
            .current_dir(&clone)
            .env("PATH", &path)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "quickstart block {} failed ({}):\n{block}\nstdout:\n{}\nstderr:\n{}",
            i + 1,
            o.status,
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
        for out in outputs(block) {
            assert!(
                non_empty(&clone.join(&out)),
                "quickstart block {} did not write {out}:\n{block}",
                i + 1
            );
        }
    }
}
