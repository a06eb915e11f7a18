//! Sample caching (§7.2): per selected box, samples quantized to an object-space grid, reused
//! while the box's distance stays within a constant factor, evicted least-recently-used under
//! a fixed memory bound.
//!
//! Deviation: the paper builds a box's set the first time the box is selected. Over a
//! walkthrough that moves far between frames (a flyover) most boxes are then selected once, and
//! a set costs more than the fresh samples it replaces (it is built at `tolerance²` density and
//! quantized), so caching made such walks slower. Here a set is built only for a box that was
//! also selected in the frame before at a distance within `√tolerance` of today's: at that
//! speed the set stays valid for the next two frames, which repays its build (about 1.6
//! frames of fresh samples). A box seen for the first time, or approaching or receding faster,
//! is sampled fresh; a static camera draws fresh samples in its first frame, builds in the
//! second and draws cached sets from the third on. Sets are still per box: what a new view
//! needs that is missing is built, nothing else.

use std::collections::{HashMap, HashSet};

use occult_core::{ItemId, Vec3};

use super::sample::key_hash;
use crate::hash::{FxBuild, FxHasher};

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
/// Frames a box whose set did not fit is sampled fresh before it may be built again.
pub const DECLINE_FRAMES: u64 = 8;
/// The longest a declined box waits: each decline of a box declined before doubles its wait.
pub const DECLINE_MAX_FRAMES: u64 = 1024;
/// Bytes one remembered request costs (key fingerprint, distance, hash table slot, estimated).
const SEEN_BYTES: usize = 24;

/// Identifies a box across frames: structure, structure instance (its first item id, unique
/// per instance path) and list section.
pub type BoxKey = (u32, ItemId, u32, u32);

/// Fx over a key's words, then a SplitMix64 finaliser: the table takes its bucket from the low
/// bits, which Fx alone leaves equal for keys whose words differ only in high bits (item ids of
/// instances are multiples of large counts), so that millions of keys shared a few buckets.
#[derive(Default, Clone, Copy)]
struct KeyHasher(FxHasher);

impl std::hash::Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        super::sample::mix(self.0.finish())
    }
    fn write(&mut self, bytes: &[u8]) {
        self.0.write(bytes);
    }
    fn write_u32(&mut self, i: u32) {
        self.0.write_u32(i);
    }
    fn write_u64(&mut self, i: u64) {
        self.0.write_u64(i);
    }
}

type KeyBuild = std::hash::BuildHasherDefault<KeyHasher>;

/// What to do with a selected box's samples this frame ([`SampleCache::plan`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Plan {
    /// A valid set is cached: draw it.
    Hit,
    /// No valid set, but the box was selected in the frame before at a similar distance: build
    /// one (it will likely be reused).
    Build,
    /// Sample it fresh (and remember the request, [`SampleCache::note`]).
    Direct,
}

struct Entry {
    samples: Vec<CachedSample>,
    /// View distance the entry was built for (its density suits `[z/tolerance, z·tolerance]`).
    z_built: f32,
    last_used: u64,
}

/// The LRU cache of sample sets under a byte budget, with the boxes requested in the current
/// and the previous frame (the admission rule, see the module notes).
pub struct SampleCache {
    map: HashMap<BoxKey, Entry, KeyBuild>,
    /// Eviction order: `(last_used, key)` of the entries when it was made, newest first, so
    /// that the least recently used is popped from the end. An entry used or replaced since
    /// no longer matches its element and is skipped; entries added since are newer than every
    /// element. Made anew when empty: touching an entry costs no reordering.
    queue: Vec<(u64, BoxKey)>,
    bytes: usize,
    budget: usize,
    tolerance: f32,
    /// Requests of this frame without a valid set: [`key_hash`] of the key (a collision can
    /// only build a set that was not asked for twice) → distance.
    seen: HashMap<u64, f32, FxBuild>,
    /// The same for the frame before.
    seen_before: HashMap<u64, f32, FxBuild>,
    /// Boxes whose set did not fit beside the sets of its frame → (first frame it may be
    /// built again, its wait): [`DECLINE_FRAMES`], doubled at each decline while remembered
    /// (one more wait after it ends).
    declined: HashMap<u64, (u64, u64), FxBuild>,
}

impl SampleCache {
    /// An empty cache holding at most `budget` bytes, reusing a set while the box's nearest
    /// distance is within a factor `tolerance` (> 1) of the one it was built for.
    pub fn new(budget: usize, tolerance: f32) -> Self {
        Self {
            map: HashMap::default(),
            queue: Vec::new(),
            bytes: 0,
            budget,
            tolerance,
            seen: HashMap::default(),
            seen_before: HashMap::default(),
            declined: HashMap::default(),
        }
    }

    /// Bytes held by the sets (samples plus bookkeeping); never above the budget.
    pub fn bytes(&self) -> usize {
        self.bytes
    }

    /// Bytes of the remembered requests of two frames (outside the budget: at most two frames'
    /// selected boxes).
    pub fn seen_bytes(&self) -> usize {
        (self.seen.capacity() + self.seen_before.capacity()) * SEEN_BYTES
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

    /// What to do with box `key` at nearest distance `z_min` in `frame` (changes nothing).
    pub fn plan(&self, key: &BoxKey, z_min: f32, frame: u64) -> Plan {
        if self.map.get(key).is_some_and(|e| self.valid(e, z_min)) {
            return Plan::Hit;
        }
        let f = key_hash(key);
        if self.declined.get(&f).is_some_and(|&(until, _)| frame < until) {
            return Plan::Direct;
        }
        let near = |z: f32| {
            let r = if z > z_min { z / z_min } else { z_min / z };
            r * r <= self.tolerance
        };
        match self.seen.get(&f).or_else(|| self.seen_before.get(&f)) {
            Some(&z) if near(z) => Plan::Build,
            _ => Plan::Direct,
        }
    }

    /// Remembers a request of box `key` at `z_min` that was sampled fresh ([`Plan::Direct`]).
    pub fn note(&mut self, key: &BoxKey, z_min: f32) {
        self.seen.insert(key_hash(key), z_min);
    }

    /// Ends `frame`: its requests become the frame before's, those of the frame before are
    /// forgotten, and so are declined boxes one wait after theirs ended.
    pub fn end_frame(&mut self, frame: u64) {
        std::mem::swap(&mut self.seen, &mut self.seen_before);
        self.seen.clear();
        self.declined.retain(|_, &mut (until, wait)| frame + 1 < until + wait);
    }

    fn valid(&self, e: &Entry, z_min: f32) -> bool {
        z_min * self.tolerance >= e.z_built && z_min <= e.z_built * self.tolerance
    }

    /// Marks the set of `key` used in `frame` (after [`Plan::Hit`]).
    pub fn touch(&mut self, key: &BoxKey, frame: u64) {
        if let Some(e) = self.map.get_mut(key) {
            e.last_used = frame;
        }
    }

    /// True when `key` has a set valid at nearest distance `z_min`, which is then marked used
    /// in `frame`.
    pub fn lookup(&mut self, key: &BoxKey, z_min: f32, frame: u64) -> bool {
        let hit = self.map.get(key).is_some_and(|e| self.valid(e, z_min));
        if hit {
            self.touch(key, frame);
        }
        hit
    }

    /// The samples of `key` (after a successful [`SampleCache::lookup`]).
    pub fn samples(&self, key: &BoxKey) -> &[CachedSample] {
        self.map.get(key).map_or(&[], |e| &e.samples)
    }

    /// True when a set of `sample_count` samples fits the budget at all.
    pub fn fits(&self, sample_count: f64) -> bool {
        sample_count * SAMPLE_BYTES as f64 + ENTRY_BYTES as f64 <= self.budget as f64
    }

    /// Stores `samples` for `key`, built in `frame`, replacing a stale set and evicting the
    /// least recently used sets of earlier frames until the budget holds. Returns the number
    /// of sets evicted. A set that does not fit beside the sets used in `frame` is not stored,
    /// and its box is sampled fresh for [`DECLINE_FRAMES`] frames, twice as long at each
    /// decline that follows (up to [`DECLINE_MAX_FRAMES`]): a view whose sets exceed the
    /// budget would otherwise evict its own sets and rebuild them frame after frame.
    pub fn insert(&mut self, key: BoxKey, samples: Vec<CachedSample>, z_built: f32, frame: u64) -> u64 {
        self.remove(&key);
        let need = samples.len() * SAMPLE_BYTES + ENTRY_BYTES;
        let mut evicted = 0;
        while need <= self.budget && self.bytes + need > self.budget && self.evict_one(frame) {
            evicted += 1;
        }
        if self.bytes + need > self.budget {
            let wait = match self.declined.get(&key_hash(&key)) {
                Some(&(_, wait)) => (wait * 2).min(DECLINE_MAX_FRAMES),
                None => DECLINE_FRAMES,
            };
            self.declined.insert(key_hash(&key), (frame + wait, wait));
            return evicted;
        }
        self.bytes += need;
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

    /// Removes the least recently used set (ties by key) if it was last used before `frame`;
    /// false when there is none.
    fn evict_one(&mut self, frame: u64) -> bool {
        loop {
            let Some(&(used, key)) = self.queue.last() else {
                if self.map.is_empty() {
                    return false;
                }
                self.queue = self.map.iter().map(|(k, e)| (e.last_used, *k)).collect();
                self.queue.sort_unstable_by(|a, b| b.cmp(a));
                continue;
            };
            if self.map.get(&key).is_none_or(|e| e.last_used != used) {
                self.queue.pop();
                continue;
            }
            if used >= frame {
                return false;
            }
            self.queue.pop();
            self.remove(&key);
            return true;
        }
    }

    fn remove(&mut self, key: &BoxKey) {
        if let Some(e) = self.map.remove(key) {
            self.bytes -= e.samples.len() * SAMPLE_BYTES + ENTRY_BYTES;
        }
    }
}

/// §7.2: snaps points to the centres of a grid of side `cell` and keeps one per cell (the
/// first), removing the oversampling of random selection.
///
/// Cells are told apart by one 64-bit word (21 bits an axis from the lowest cell) where the
/// points span fewer than 2^21 cells an axis, as a selected box does: the table is a third of
/// that of three 64-bit coordinates, and a set's build (at `tolerance²` times a view's samples,
/// ~25 a kept cell) spends most of its time in it.
pub fn quantize(points: &[(Vec3, ItemId)], cell: f32) -> Vec<CachedSample> {
    let inv = 1.0 / cell as f64;
    // floor without a call into the C library (the values are far inside i64's range).
    let floor = |v: f64| {
        let t = v as i64;
        t - (v < t as f64) as i64
    };
    let cell_of = |p: Vec3| {
        [
            floor(p.x as f64 * inv),
            floor(p.y as f64 * inv),
            floor(p.z as f64 * inv),
        ]
    };
    let centre = |k: [i64; 3]| {
        let c = |i: i64| ((i as f64 + 0.5) * cell as f64) as f32;
        Vec3::new(c(k[0]), c(k[1]), c(k[2]))
    };
    let (mut lo, mut hi) = ([i64::MAX; 3], [i64::MIN; 3]);
    for &(p, _) in points {
        let k = cell_of(p);
        for a in 0..3 {
            lo[a] = lo[a].min(k[a]);
            hi[a] = hi[a].max(k[a]);
        }
    }
    const BITS: u32 = 21;
    let packed = (0..3).all(|a| hi[a].checked_sub(lo[a]).is_some_and(|d| d < 1 << BITS));
    let mut out = Vec::new();
    if packed {
        let mut seen: HashSet<u64, KeyBuild> = HashSet::with_capacity_and_hasher(points.len() / 8, KeyBuild::default());
        for &(p, item) in points {
            let k = cell_of(p);
            let word =
                ((k[0] - lo[0]) as u64) | ((k[1] - lo[1]) as u64) << BITS | ((k[2] - lo[2]) as u64) << (2 * BITS);
            if seen.insert(word) {
                out.push(CachedSample {
                    position: centre(k),
                    item,
                });
            }
        }
    } else {
        let mut seen: HashSet<[i64; 3], KeyBuild> =
            HashSet::with_capacity_and_hasher(points.len() / 8, KeyBuild::default());
        for &(p, item) in points {
            let k = cell_of(p);
            if seen.insert(k) {
                out.push(CachedSample {
                    position: centre(k),
                    item,
                });
            }
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

    /// A set that does not fit beside its own frame's sets is not stored; its box is sampled
    /// fresh for DECLINE_FRAMES, then twice as long after a second decline.
    #[test]
    fn sets_that_do_not_fit_beside_their_frame_are_declined_with_a_growing_wait() {
        let budget = 2 * (100 * SAMPLE_BYTES + ENTRY_BYTES);
        let mut c = SampleCache::new(budget, 1.5);
        let key = (9, 0, 0, 1);
        c.insert((0, 0, 0, 1), set(100), 1.0, 1);
        c.insert((0, 1, 0, 1), set(100), 1.0, 1);
        assert_eq!(c.insert(key, set(100), 1.0, 1), 0);
        assert_eq!(c.len(), 2);
        c.note(&key, 1.0);
        c.end_frame(1);
        assert_eq!(c.plan(&key, 1.0, 2), Plan::Direct);
        assert_eq!(c.plan(&key, 1.0, 1 + DECLINE_FRAMES - 1), Plan::Direct);
        // The wait over (and the box seen the frame before): built again, declined again.
        let f = 1 + DECLINE_FRAMES;
        c.note(&key, 1.0);
        c.end_frame(f - 1);
        assert_eq!(c.plan(&key, 1.0, f), Plan::Build);
        c.touch(&(0, 0, 0, 1), f);
        c.touch(&(0, 1, 0, 1), f);
        c.insert(key, set(100), 1.0, f);
        assert_eq!(c.plan(&key, 1.0, f + 2 * DECLINE_FRAMES - 1), Plan::Direct);
        // Sets of earlier frames are evicted for it.
        assert_eq!(c.insert((9, 1, 0, 1), set(100), 1.0, f + 1), 1);
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
        let q = quantize(&pts, 1.0);
        assert_eq!(q.len(), 2);
        assert_eq!(q[0].item, 1);
        assert_eq!(q[0].position, Vec3::splat(0.5));
        assert_eq!(q[1].position, Vec3::new(1.5, 0.5, 0.5));
        // Cells far apart (beyond 2^21 an axis) and negative coordinates: the same rule.
        let far = [
            (Vec3::new(-0.5, 0.2, 0.0), 1),
            (Vec3::new(-0.7, 0.9, 0.1), 2),
            (Vec3::new(3.0e6, 0.0, 0.0), 3),
            (Vec3::new(-0.1, 0.0, 0.0), 4),
        ];
        let q = quantize(&far, 1.0);
        assert_eq!(q.iter().map(|s| s.item).collect::<Vec<_>>(), [1, 3]);
        assert_eq!(q[0].position, Vec3::new(-0.5, 0.5, 0.5));
        assert!(quantize(&[], 1.0).is_empty());
    }
}
