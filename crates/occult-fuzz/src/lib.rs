//! # occult-fuzz
//!
//! The fuzz targets of the file loaders, written once: cargo-fuzz's targets in `fuzz/` (nightly,
//! libFuzzer, outside the workspace) call [`Target::run`], and this crate's tests replay the
//! committed corpus `fuzz/corpus/<target>/` through the same call on stable, so CI needs no
//! nightly. The `fuzz-seeds` binary writes the seed corpus (see `docs/loaders.md`).
//!
//! One input is one model held in memory, with its companion file after a [`COMPANION_MARKER`]:
//! - [`Target::Obj`]: an OBJ; the companion is `m.mtl` beside it (`mtllib m.mtl`), and `t.png`
//!   exists there too (an empty file, for the texture check).
//! - [`Target::PlyAscii`], [`Target::PlyBinaryLe`], [`Target::PlyBinaryBe`]: a PLY without its
//!   first two lines; the target writes `ply` and the `format` line of its encoding, so every
//!   input exercises that encoding (no companion).
//! - [`Target::Gltf`]: a `.gltf` JSON or a GLB (the loader tells them apart by content); the
//!   companion is `b.bin` beside it, for buffers with `"uri": "b.bin"`.
//!
//! Companions are served from memory ([`occult_scenes::load::load_bytes_with`]), so a target
//! does no file I/O. A target asserts what DESIGN invariant 5 asks of every input: the load
//! returns (a scene or an error) without a panic, and an error names the file. Hangs are the
//! fuzzer's to catch (`-timeout`), and so are allocations past the bound: libFuzzer's
//! `-rss_limit_mb` and `-malloc_limit_mb` (the latter only in sanitizer builds), and the
//! [`CappedAllocator`] the targets install, which aborts on any single allocation larger than
//! [`allocation_cap`] of the input being loaded (proportional to its size).
//!
//! ```
//! use occult_fuzz::Target;
//! let loaded = Target::Obj.run(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
//! assert_eq!(loaded.expect("a triangle").scene.item_count(), 1);
//! assert!(Target::PlyBinaryBe.run(b"element vertex 99999999999\nend_header\n").is_err());
//! ```
#![deny(missing_docs)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use occult_scenes::load::{load_bytes_with, LoadError, LoadedScene};

/// The line that separates a model from its companion file in a fuzz input.
pub const COMPANION_MARKER: &[u8] = b"\n#%companion%\n";

/// The folder a target's model is placed in (never read: companions come from memory).
const FOLDER: &str = "fuzz";

/// One fuzz target: a loader and the encoding it is held to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// Wavefront OBJ, with an `.mtl` companion.
    Obj,
    /// PLY, ascii.
    PlyAscii,
    /// PLY, binary little-endian.
    PlyBinaryLe,
    /// PLY, binary big-endian.
    PlyBinaryBe,
    /// glTF JSON or GLB, with a `.bin` companion.
    Gltf,
}

impl Target {
    /// Every target, in the order the campaign runs them.
    pub const ALL: [Target; 5] = [
        Target::Obj,
        Target::PlyAscii,
        Target::PlyBinaryLe,
        Target::PlyBinaryBe,
        Target::Gltf,
    ];

    /// The target's name: its cargo-fuzz target and its corpus folder (`fuzz/corpus/<name>`).
    pub fn name(self) -> &'static str {
        match self {
            Target::Obj => "obj",
            Target::PlyAscii => "ply_ascii",
            Target::PlyBinaryLe => "ply_binary_le",
            Target::PlyBinaryBe => "ply_binary_be",
            Target::Gltf => "gltf",
        }
    }

    /// The target named `name` ([`Target::name`]).
    pub fn from_name(name: &str) -> Option<Target> {
        Target::ALL.into_iter().find(|t| t.name() == name)
    }

    /// The PLY `format` line this target writes, for the PLY targets.
    pub fn ply_format(self) -> Option<&'static str> {
        match self {
            Target::PlyAscii => Some("ascii"),
            Target::PlyBinaryLe => Some("binary_little_endian"),
            Target::PlyBinaryBe => Some("binary_big_endian"),
            Target::Obj | Target::Gltf => None,
        }
    }

    /// Loads one fuzz input (see the crate doc for its layout).
    ///
    /// # Errors
    /// What the loader returns for a bad model.
    ///
    /// # Panics
    /// When the loader panics (the bug a fuzzer looks for), or when an error does not name the
    /// model file.
    pub fn run(self, input: &[u8]) -> Result<LoadedScene, LoadError> {
        INPUT_LEN.store(input.len(), Ordering::Relaxed);
        let (model, companion) = split_companion(input);
        let (name, companion_name) = match self {
            Target::Obj => ("model.obj", "m.mtl"),
            Target::Gltf => ("model.gltf", "b.bin"),
            _ => ("model.ply", "unused"),
        };
        let path = Path::new(FOLDER).join(name);
        let mut files: HashMap<PathBuf, Vec<u8>> = HashMap::new();
        files.insert(
            Path::new(FOLDER).join(companion_name),
            companion.unwrap_or_default().to_vec(),
        );
        files.insert(Path::new(FOLDER).join("t.png"), Vec::new());
        let result = match self.ply_format() {
            Some(format) => {
                let mut ply = format!("ply\nformat {format} 1.0\n").into_bytes();
                ply.extend_from_slice(input);
                load_bytes_with(&path, &ply, &files)
            }
            None => load_bytes_with(&path, model, &files),
        };
        if let Err(e) = &result {
            // An error names the model or, for a companion's fault, the companion.
            let names_a_file = e.path().starts_with(FOLDER);
            assert!(names_a_file, "error does not name the file: {e}");
            assert!(!e.to_string().contains('\n'), "error of more than one line: {e}");
        }
        result
    }
}

/// The length of the input being loaded, for [`CappedAllocator`].
static INPUT_LEN: AtomicUsize = AtomicUsize::new(0);

/// The largest single allocation a load of `input_len` bytes may make: 8 MiB plus 1024 bytes per
/// input byte. The loaders' own growth is a small multiple of the input (a `u8` strip index
/// becomes a 12-byte triangle; a meshopt stream expands at most 64-fold, checked before
/// decoding); a count taken from a file without the check against the bytes present allocates
/// gigabytes and lands far above.
pub fn allocation_cap(input_len: usize) -> usize {
    (8 << 20) + input_len.saturating_mul(1024)
}

/// The system allocator, aborting (a crash libFuzzer records with its input) on an allocation
/// larger than [`allocation_cap`] of the input [`Target::run`] is loading. It works without a
/// sanitizer, where libFuzzer's `-malloc_limit_mb` does not.
pub struct CappedAllocator;

// SAFETY: every call forwards to `System` with the caller's arguments; the check before it
// only reads an atomic and may abort.
unsafe impl GlobalAlloc for CappedAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        check_size(layout.size());
        // SAFETY: forwarded unchanged; the caller upholds `GlobalAlloc::alloc`'s contract.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        check_size(layout.size());
        // SAFETY: as `alloc`.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `System` through this allocator, with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        check_size(new_size);
        // SAFETY: as `dealloc`; `new_size` is the caller's, per `GlobalAlloc::realloc`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

fn check_size(size: usize) {
    let cap = allocation_cap(INPUT_LEN.load(Ordering::Relaxed));
    if size > cap {
        // No allocation here (the message is static): this runs inside the allocator.
        let message = b"occult-fuzz: an allocation larger than the cap for this input; aborting\n";
        let _ = std::io::Write::write_all(&mut std::io::stderr(), message);
        std::process::abort();
    }
}

/// The model and its companion (after the first [`COMPANION_MARKER`]).
fn split_companion(input: &[u8]) -> (&[u8], Option<&[u8]>) {
    match input
        .windows(COMPANION_MARKER.len())
        .position(|w| w == COMPANION_MARKER)
    {
        Some(at) => (&input[..at], Some(&input[at + COMPANION_MARKER.len()..])),
        None => (input, None),
    }
}

/// A fuzz input of `model` with `companion` after it.
pub fn with_companion(model: &[u8], companion: &[u8]) -> Vec<u8> {
    [model, COMPANION_MARKER, companion].concat()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for target in Target::ALL {
            assert_eq!(Target::from_name(target.name()), Some(target));
        }
        assert_eq!(Target::from_name("stl"), None);
    }

    #[test]
    fn companion_splits_at_the_first_marker() {
        let input = with_companion(b"model", &with_companion(b"a", b"b"));
        let (model, companion) = split_companion(&input);
        assert_eq!(model, b"model");
        assert_eq!(companion, Some(&with_companion(b"a", b"b")[..]));
        assert_eq!(split_companion(b"plain"), (&b"plain"[..], None));
    }

    #[test]
    fn obj_reads_its_mtl_companion() {
        let obj = b"mtllib m.mtl\nusemtl red\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
        let mtl = b"newmtl red\nKd 1 0 0\nmap_Kd t.png\nmap_Ka gone.png\n";
        let loaded = Target::Obj.run(&with_companion(obj, mtl)).expect("loads");
        assert_eq!(loaded.scene.item_count(), 1);
        assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
        assert!(loaded.warnings[0].contains("gone.png"), "{:?}", loaded.warnings);
    }

    #[test]
    fn ply_targets_write_their_format_line() {
        let body = b"element vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
        assert_eq!(Target::PlyAscii.run(body).expect("ascii").scene.item_count(), 1);
        assert!(Target::PlyBinaryLe.run(body).is_err());
    }
}
