//! Sample caching (§7.2): per selected box, samples quantized to an object-space grid, reused
//! while the box's distance stays within a constant factor, evicted least-recently-used under
//! a fixed memory bound.

use std::collections::{BTreeSet, HashMap};

use occult_core::{ItemId, Vec3};

/// A cached sample: a quantized point in its structure's space and its item id relative to
/// the structure instance's first.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CachedSample {
    /// Position (structure space), snapped to the centre of its grid cell.
    pub position: Vec3,
    /// Item id relative to the box's base.
    pub item: ItemId,
}

/// Bytes one cached sample costs.
pub const SAMPLE_BYTES: usize = std::mem::size_of::<CachedSample>();
/// Bytes one cache entry costs beyond its samples (map and LRU bookkeeping, estimated).
pub const ENTRY_BYTES: usize = 128;

/// Identifies a box across frames: structure, structure instance (its first item id, unique
/// per instance path) and list section.
pub type BoxKey = (u32, ItemId, u32, u32);

struct Entry {
    samples: Vec<CachedSample>,
    /// View distance the entry was built for (its density suits `[z/tolerance, z·tolerance]`).
    z_built: f32,
    last_used: u64,
}

/// The LRU cache of sample sets under a byte budget.
pub struct SampleCache {
    map: HashMap<BoxKey, Entry>,
    lru: BTreeSet<(u64, BoxKey)>,
    bytes: usize,
    budget: usize,
    tolerance: f32,
}

impl SampleCache {
    /// An empty cache holding at most `budget` bytes, reusing a set while the box's nearest
    /// distance is within a factor `tolerance` (> 1) of the one it was built for.
    pub fn new(budget: usize, tolerance: f32) -> Self {
        Self {
            map: HashMap::new(),
            lru: BTreeSet::new(),
            bytes: 0,
            budget,
            tolerance,
        }
    }

    /// Bytes held (samples plus bookkeeping); never above the budget.
    pub fn bytes(&self) -> usize {
        self.bytes
    }

    /// The budget in bytes.
    pub fn budget(&self) -> usize {
        self.budget
    }

    /// Entries held.
    pub fn len(&self) -> usize {
        self.map.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }

    /// The samples of `key` if valid at nearest distance `z_min`, marking them used in `frame`.
    pub fn lookup(&mut self, key: &BoxKey, z_min: f32, frame: u64) -> bool {
        let Some(e) = self.map.get_mut(key) else {
            return false;
        };
        if !(z_min * self.tolerance >= e.z_built && z_min <= e.z_built * self.tolerance) {
            return false;
        }
        self.lru.remove(&(e.last_used, *key));
        e.last_used = frame;
        self.lru.insert((frame, *key));
        true
    }

    /// The samples of `key` (after a successful [`SampleCache::lookup`]).
    pub fn samples(&self, key: &BoxKey) -> &[CachedSample] {
        self.map.get(key).map_or(&[], |e| &e.samples)
    }

    /// True when a set of `sample_count` samples fits the budget at all.
    pub fn fits(&self, sample_count: f64) -> bool {
        sample_count * SAMPLE_BYTES as f64 + ENTRY_BYTES as f64 <= self.budget as f64
    }

    /// Stores `samples` for `key`, replacing a stale set and evicting the least recently used
    /// sets until the budget holds. Returns the number of sets evicted. A set larger than the
    /// whole budget is not stored.
    pub fn insert(&mut self, key: BoxKey, samples: Vec<CachedSample>, z_built: f32, frame: u64) -> u64 {
        self.remove(&key);
        let need = samples.len() * SAMPLE_BYTES + ENTRY_BYTES;
        if need > self.budget {
            return 0;
        }
        let mut evicted = 0;
        while self.bytes + need > self.budget {
            let Some(&(_, old)) = self.lru.iter().next() else {
                break;
            };
            self.remove(&old);
            evicted += 1;
        }
        self.bytes += need;
        self.lru.insert((frame, key));
        self.map.insert(
            key,
            Entry {
                samples,
                z_built,
                last_used: frame,
            },
        );
        evicted
    }

    fn remove(&mut self, key: &BoxKey) {
        if let Some(e) = self.map.remove(key) {
            self.lru.remove(&(e.last_used, *key));
            self.bytes -= e.samples.len() * SAMPLE_BYTES + ENTRY_BYTES;
        }
    }
}

/// §7.2: snaps points to the centres of a grid of side `cell` and keeps one per cell (the
/// first), removing the oversampling of random selection.
pub fn quantize(points: impl Iterator<Item = (Vec3, ItemId)>, cell: f32) -> Vec<CachedSample> {
    let mut seen: HashMap<[i64; 3], ()> = HashMap::new();
    let mut out = Vec::new();
    let inv = 1.0 / cell as f64;
    for (p, item) in points {
        let k = [
            (p.x as f64 * inv).floor() as i64,
            (p.y as f64 * inv).floor() as i64,
            (p.z as f64 * inv).floor() as i64,
        ];
        if seen.insert(k, ()).is_none() {
            let q = Vec3::new(
                ((k[0] as f64 + 0.5) * cell as f64) as f32,
                ((k[1] as f64 + 0.5) * cell as f64) as f32,
                ((k[2] as f64 + 0.5) * cell as f64) as f32,
            );
            out.push(CachedSample { position: q, item });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(n: usize) -> Vec<CachedSample> {
        vec![
            CachedSample {
                position: Vec3::ZERO,
                item: 0
            };
            n
        ]
    }

    #[test]
    fn lru_eviction_keeps_the_budget() {
        let budget = 10 * (100 * SAMPLE_BYTES + ENTRY_BYTES);
        let mut c = SampleCache::new(budget, 1.5);
        let mut evicted = 0;
        for f in 0..50u64 {
            evicted += c.insert((0, f, 0, 1), set(100), 1.0, f);
            assert!(c.bytes() <= budget);
        }
        assert_eq!(c.len(), 10);
        assert_eq!(evicted, 40);
        // The most recent survive; touching one protects it from the next eviction.
        assert!(c.lookup(&(0, 40, 0, 1), 1.0, 60));
        c.insert((1, 0, 0, 1), set(100), 1.0, 61);
        assert!(c.lookup(&(0, 40, 0, 1), 1.0, 62));
        assert!(!c.lookup(&(0, 41, 0, 1), 1.0, 62));
        // Too large for the budget: not stored.
        assert_eq!(c.insert((2, 0, 0, 1), set(100_000), 1.0, 63), 0);
        assert!(!c.lookup(&(2, 0, 0, 1), 1.0, 64));
    }

    #[test]
    fn validity_follows_the_distance_tolerance() {
        let mut c = SampleCache::new(1 << 20, 1.5);
        c.insert((0, 0, 0, 1), set(3), 10.0, 0);
        assert!(c.lookup(&(0, 0, 0, 1), 14.0, 1));
        assert!(c.lookup(&(0, 0, 0, 1), 7.0, 1));
        assert!(!c.lookup(&(0, 0, 0, 1), 16.0, 1));
        assert!(!c.lookup(&(0, 0, 0, 1), 6.0, 1));
    }

    #[test]
    fn quantize_keeps_one_point_per_cell() {
        let pts = [
            (Vec3::new(0.1, 0.1, 0.1), 1),
            (Vec3::new(0.2, 0.3, 0.4), 2),
            (Vec3::new(1.5, 0.1, 0.1), 3),
        ];
        let q = quantize(pts.into_iter(), 1.0);
        assert_eq!(q.len(), 2);
        assert_eq!(q[0].item, 1);
        assert_eq!(q[0].position, Vec3::splat(0.5));
        assert_eq!(q[1].position, Vec3::new(1.5, 0.5, 0.5));
    }
}
