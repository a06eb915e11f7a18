//! The hasher of the renderers' per-frame sets and maps, whose keys are ids (nodes, items,
//! leaves), never attacker data: one multiply and rotate per word (Fx, as in rustc), much
//! cheaper than the standard library's SipHash.

use std::hash::{BuildHasherDefault, Hasher};

/// A fast hasher for integer keys (Fx, as in rustc). Its output is part of the behaviour
/// where a hash chooses work (hzb's hybrid distribution), so it must not change.
#[derive(Default, Clone, Copy)]
pub(crate) struct FxHasher(u64);

impl Hasher for FxHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    fn write_u32(&mut self, i: u32) {
        self.write_u64(i as u64);
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

/// Builds [`FxHasher`]s: the `S` of `HashMap<K, V, S>` and `HashSet<K, S>`.
pub(crate) type FxBuild = BuildHasherDefault<FxHasher>;
