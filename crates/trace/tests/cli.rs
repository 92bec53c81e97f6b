//! The `hytrace` binary end to end: the README's main command, round trips, and bad input.

use std::process::{Command, Output};

use hytrace_foundry::Foundry;
use hytrace_trace::scene::default_scene;

fn hytrace(args: &[&std::ffi::OsStr]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hytrace"))
        .args(args)
        .output()
        .unwrap()
}

fn s(v: &str) -> &std::ffi::OsStr {
    v.as_ref()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn foundry_command_writes_the_default_scene() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("default-foundry");
    let o = hytrace(&[s("foundry"), s("-o"), out.as_os_str()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let expected = default_scene().unwrap();
    assert_eq!(Foundry::load(&out).unwrap(), expected);
    // `info` on the written directory reports the same counts as the embedded scene.
    let o = hytrace(&[s("info"), out.as_os_str(), s("--json")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(
        text.contains(&format!("\"instances\":{}", expected.inst.len())),
        "{text}"
    );
    assert!(
        text.contains(&format!("\"solids\":{}", expected.solid.len())),
        "{text}"
    );
}

#[test]
fn bad_scene_arguments_give_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("nope");
    let o = hytrace(&[s("info"), missing.as_os_str()]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("nope") && stderr(&o).contains("no such file"),
        "{}",
        stderr(&o)
    );

    let file = tmp.path().join("scene.xyz");
    std::fs::write(&file, "garbage").unwrap();
    let o = hytrace(&[s("info"), file.as_os_str()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("scene.xyz"), "{}", stderr(&o));

    // A corrupt store: the error names the file, and nothing panics.
    let store = tmp.path().join("store");
    default_scene().unwrap().save(&store).unwrap();
    std::fs::write(store.join("prim.npy"), b"\x93NUMPY\x01\x00").unwrap();
    let o = hytrace(&[s("info"), store.as_os_str()]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("prim.npy") && !stderr(&o).contains("panicked"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn failed_write_leaves_no_partial_output() {
    let tmp = tempfile::tempdir().unwrap();
    let blocker = tmp.path().join("file");
    std::fs::write(&blocker, "not a directory").unwrap();
    let out = blocker.join("store");
    let o = hytrace(&[s("foundry"), s("-o"), out.as_os_str()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("file"), "{}", stderr(&o));
    let entries: Vec<_> = std::fs::read_dir(tmp.path()).unwrap().collect();
    assert_eq!(entries.len(), 1, "only the blocking file remains");
}

#[test]
fn existing_non_foundry_output_is_never_replaced() {
    let tmp = tempfile::tempdir().unwrap();
    // A user's directory and a user's file: both must survive an `-o` pointing at them.
    let dir = tmp.path().join("mydata");
    std::fs::create_dir(&dir).unwrap();
    std::fs::write(dir.join("precious.txt"), "keep me").unwrap();
    let file = tmp.path().join("notes.txt");
    std::fs::write(&file, "keep me too").unwrap();
    for target in [&dir, &file] {
        let o = hytrace(&[s("foundry"), s("-o"), target.as_os_str()]);
        assert!(!o.status.success());
        assert!(stderr(&o).contains("refusing to replace"), "{}", stderr(&o));
    }
    assert_eq!(
        std::fs::read_to_string(dir.join("precious.txt")).unwrap(),
        "keep me"
    );
    assert_eq!(std::fs::read_to_string(&file).unwrap(), "keep me too");
    // An existing Foundry directory is replaced.
    let store = tmp.path().join("store");
    let o = hytrace(&[s("foundry"), s("-o"), store.as_os_str()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = hytrace(&[s("foundry"), s("-o"), store.as_os_str()]);
    assert!(o.status.success(), "{}", stderr(&o));
}
