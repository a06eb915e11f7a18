//! End-to-end tests of the `occult` binary, one test binary: small generated scenes, small
//! frames, and bad input that must end in one line on stderr and a non-zero status, never a
//! panic. `commands` covers render, walk, compare, sweep, info, scenes and algos; `nbuffer`
//! covers particles and shadows (Décoret 2005 §3.2, §3.3); `suite` the performance yardstick; `mpi` (feature `mpi`) the same commands under `mpirun`.

mod commands;
#[cfg(feature = "mpi")]
mod mpi;
mod nbuffer;
mod suite;

use std::path::PathBuf;
use std::process::{Command, Output};

use serde_json::Value;

/// Small scenes: fast on two cores in CI.
pub const TERRAIN: &str = "terrain:g=24";
pub const CITY: &str = "city:blocks=1,detail=1,variants=2";

fn occult(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_occult"))
        .args(args)
        .output()
        .expect("the occult binary runs")
}

/// A fresh directory for one test's files.
fn scratch(test: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("occult-cli-tests")
        .join(test);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn path_arg(p: &std::path::Path) -> &str {
    p.to_str().expect("test paths are UTF-8")
}

/// The paths of files `names` in a fresh [`scratch`] directory for `test`, as text.
fn scratch_files<const N: usize>(test: &str, names: [&str; N]) -> [String; N] {
    let dir = scratch(test);
    names.map(|name| path_arg(&dir.join(name)).to_string())
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Asserts success and returns stdout.
fn ok(args: &[&str]) -> String {
    let out = occult(args);
    assert!(out.status.success(), "occult {args:?} failed: {}", text(&out.stderr));
    text(&out.stdout)
}

fn read_json(p: &std::path::Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// Status, stdout and stderr of a run that must fail.
fn fails(args: &[&str]) -> (Option<i32>, String, String) {
    let out = occult(args);
    assert!(!out.status.success(), "occult {args:?} succeeded");
    let stderr = text(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "occult {args:?}: {stderr}");
    (out.status.code(), text(&out.stdout), stderr)
}
