//! Fuzz target `gltf`: one input through `occult_fuzz::Target::Gltf` (see that crate's doc).
#![no_main]

use libfuzzer_sys::fuzz_target;
use occult_fuzz::{CappedAllocator, Target};

#[global_allocator]
static ALLOCATOR: CappedAllocator = CappedAllocator;

fuzz_target!(|data: &[u8]| {
    // Ok or a typed error are both fine; a panic, a hang or an allocation past the limits is
    // the finding.
    let _ = Target::Gltf.run(data);
});
