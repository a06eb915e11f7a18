//! Sample generation (§5.2, §5.3.3, §7.3) and per-pixel / splatting reconstruction (§4.1,
//! §4.2).

use occult_core::{Instance, ItemId, Mat4, NodeKind, Scene, Vec3};
use occult_raster::keep_fragment;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

use super::cache::{BoxKey, CachedSample};
use super::select::Job;
use super::structure::{Link, Structure};

/// Where samples are written: depth and item buffers of a `width × height` frame.
pub struct Target<'f> {
    /// Depth (reversed-Z, greater is nearer).
    pub depth: &'f mut [f32],
    /// Items.
    pub items: &'f mut [ItemId],
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

/// Per-thread counts.
#[derive(Clone, Copy, Debug, Default)]
pub struct SampleCounts {
    /// Samples generated (drawn from the distribution lists).
    pub generated: u64,
    /// Of which rejected as back-facing (§5.3.3).
    pub backfacing: u64,
    /// Samples projected into the frame (inside the view).
    pub drawn: u64,
}

/// What every sample of a frame shares.
pub struct Sampler<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// Its structures.
    pub structures: &'a [Structure],
    /// Splat side `d`.
    pub splat: u32,
    /// Reject back-facing samples (§5.3.3).
    pub backface: bool,
    /// Eye in world space.
    pub eye: Vec3,
    /// Depth of the far plane (fragments with smaller depth are dropped).
    pub far_depth: f32,
    /// Renderer seed.
    pub seed: u64,
    /// Frame width in pixels.
    pub width: u32,
    /// Frame height in pixels.
    pub height: u32,
}

/// A sample projected into the view.
#[derive(Clone, Copy, Debug)]
pub struct Projected {
    /// Position in pixels (0 at the left edge), in `[0, width]`.
    pub x: f32,
    /// Position in pixels (0 at the top edge), in `[0, height]`.
    pub y: f32,
    /// Reversed-Z depth.
    pub depth: f32,
    /// Item id.
    pub item: ItemId,
}

/// Projects `p` by `clip_from_space`: `None` outside the view volume.
#[inline]
fn project(
    clip_from_space: &Mat4,
    p: Vec3,
    item: ItemId,
    width: u32,
    height: u32,
    far_depth: f32,
) -> Option<Projected> {
    let c = *clip_from_space * p.extend(1.0);
    // Reversed-Z: depth = near / w ≤ 1 in front of the near plane; NaN fails `w > 0`.
    let in_front = c.w > 0.0;
    if !in_front || c.z > c.w || c.x.abs() > c.w || c.y.abs() > c.w {
        return None;
    }
    let inv_w = 1.0 / c.w;
    let depth = c.z * inv_w;
    if depth < far_depth {
        return None;
    }
    Some(Projected {
        x: (c.x * inv_w * 0.5 + 0.5) * width as f32,
        y: (0.5 - c.y * inv_w * 0.5) * height as f32,
        depth,
        item,
    })
}

/// Samples that descend in lockstep ([`Sampler::descents`]).
const LANES: usize = 8;
/// Levels of instancing a descent carries its point up through; deeper chains are entered.
const CHAIN: usize = 16;

/// One sample's descent down the instance chain ([`Sampler::descents`]).
#[derive(Clone, Copy)]
struct Descent<'s> {
    /// The structure it is in.
    sid: u32,
    /// Item id of that structure's first triangle.
    item: ItemId,
    /// Instances entered so far (the first `depth`), as their groups' lists hold them.
    depth: usize,
    /// The list position of the triangle picked in a mesh too large for the caches, whose
    /// lines were asked for in the round before ([`FAR_SOUP`]); [`NO_LEAF`] otherwise.
    leaf: u32,
    chain: [&'s Link; CHAIN],
}

/// What an unused level of a [`Descent`]'s chain holds.
static NO_LINK: Link = Link {
    parent_from_child: occult_core::Affine3A::IDENTITY,
    child: 0,
    item_offset: 0,
};

/// [`Descent::leaf`] when no triangle waits.
const NO_LEAF: u32 = u32::MAX;
/// Meshes of more triangles than this have their picked triangle's lines asked for one
/// lockstep round before it is read: their positions (36 bytes a triangle) do not stay in the
/// caches, and reading the triangle at once made every sample wait on its miss (a third of the
/// time on the 1.4·10^14 forest, whose trees hold 19,500 triangles). Smaller meshes are read
/// at once: the extra round cost more than their hits saved (12 % on `chessboard:n=10000000`,
/// 512 triangles).
const FAR_SOUP: usize = 4096;

/// What a structure with a distribution tree samples from (§5.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// The subtree of an octree node.
    Subtree(u32),
    /// A node's own entries.
    Own(u32),
    /// Every class (an entered instance).
    Whole,
}

impl Part {
    /// The part a selected box samples from.
    pub fn of(job: &Job) -> Self {
        if job.own {
            Part::Own(job.node)
        } else {
            Part::Subtree(job.node)
        }
    }
}

/// A space samples are generated in: a structure or an instance below it.
#[derive(Clone)]
pub struct Place {
    /// To clip space.
    pub clip_from_space: Mat4,
    /// To the selected box's structure space.
    pub job_from_space: occult_core::Affine3A,
    /// The eye in this space (when rejecting back faces).
    pub eye: Vec3,
    /// Sign of the determinant from this space to world space.
    pub sign: f32,
    /// Item id of the space's first triangle.
    pub base: ItemId,
}

impl Place {
    /// The space of `job`'s structure.
    pub fn new(job: &Job, eye_world: Vec3, backface: bool) -> Self {
        Self {
            clip_from_space: job.clip_from_structure,
            job_from_space: occult_core::Affine3A::IDENTITY,
            eye: if backface {
                job.world_from_structure.inverse().transform_point3(eye_world)
            } else {
                Vec3::ZERO
            },
            sign: job.world_from_structure.matrix3.determinant().signum(),
            base: job.base,
        }
    }

    /// The space of instance `inst` (whose items start `item_offset` after this space's).
    #[inline]
    pub fn enter(&self, inst: &Instance, item_offset: u64, backface: bool) -> Self {
        self.enter_by(&inst.parent_from_child, item_offset, backface)
    }

    /// The space below transform `t` (`parent_from_child`), whose items start `item_offset`
    /// after this space's.
    #[inline]
    fn enter_by(&self, t: &occult_core::Affine3A, item_offset: u64, backface: bool) -> Self {
        Self {
            clip_from_space: self.clip_from_space * Mat4::from(*t),
            job_from_space: self.job_from_space * *t,
            eye: if backface {
                t.inverse().transform_point3(self.eye)
            } else {
                Vec3::ZERO
            },
            sign: self.sign * t.matrix3.determinant().signum(),
            base: self.base + item_offset,
        }
    }
}

/// SplitMix64 finaliser: decorrelates the per-box seeds.
#[inline]
pub(super) fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A 64-bit hash of a box's key (structure, structure instance, list section): the root of
/// its generators, and the fingerprint by which the cache remembers requests.
pub fn key_hash(&(structure, base, start, end): &BoxKey) -> u64 {
    mix(structure as u64 ^ mix(base ^ mix(((start as u64) << 32) | end as u64)))
}

/// The generator of a box: a function of the seed and the box alone, so a frame does not depend
/// on the order boxes are processed in or on the thread count.
pub fn box_rng(seed: u64, job: &Job) -> Pcg64Mcg {
    Pcg64Mcg::seed_from_u64(mix(seed ^ key_hash(&job.key())))
}

/// The generator of piece `piece` of a box's samples.
pub fn piece_rng(seed: u64, job: &Job, piece: u64) -> Pcg64Mcg {
    let h = mix(seed ^ key_hash(&job.key()));
    Pcg64Mcg::seed_from_u64(mix(h ^ mix(piece.wrapping_add(0x9e37_79b9_7f4a_7c15))))
}

/// `count` uniform points on the triangle `[a, b, c]` (entry `e` of its mesh) (§5.2), passed
/// to `f`.
#[inline]
fn points_of<F: FnMut(&Place, Vec3, Vec3, ItemId)>(
    [a, b, c]: [Vec3; 3],
    e: usize,
    count: u64,
    place: &Place,
    rng: &mut Pcg64Mcg,
    f: &mut F,
) {
    let normal = (b - a).cross(c - a);
    for _ in 0..count {
        let (r1, r2) = uniform_on_triangle(rng);
        f(place, a + (b - a) * r1 + (c - a) * r2, normal, place.base + e as u64);
    }
}

/// Barycentric weights `(r1, r2)` of a uniform point on a triangle `a + (b - a) r1 + (c - a) r2`
/// (§5.2: the unit square folded onto the triangle).
#[inline]
fn uniform_on_triangle(rng: &mut Pcg64Mcg) -> (f32, f32) {
    let (r1, r2) = (rng.random::<f32>(), rng.random::<f32>());
    if r1 + r2 > 1.0 {
        (1.0 - r1, 1.0 - r2)
    } else {
        (r1, r2)
    }
}

/// Number of samples to draw for an expectation `n`: `floor(n)` plus one with probability
/// `frac(n)`, so the expected total is exact (§4.1.1 "a · ln v").
#[inline]
pub fn sample_count(n: f64, rng: &mut Pcg64Mcg) -> u64 {
    let f = n.floor();
    f as u64 + (rng.random::<f64>() < n - f) as u64
}

impl Sampler<'_> {
    /// §5.2 and §7.3: `n` points of list positions `range` of structure `sid`, each entry
    /// chosen with probability proportional to its area, passed to `f` in the space of the
    /// mesh they lie on (with that space's [`Place`]).
    ///
    /// Each sample is chosen on its own ([`Sampler::descents`]): its position in the section
    /// `range` by inverting the distribution list (a binary search of the prefix sums), or in a
    /// whole structure by its alias table, then down the instance chain by alias picks.
    ///
    /// §5.4: a structure with a distribution tree samples from it instead: `part` (the job's
    /// node, or the whole tree for an entered instance) is descended once per sample.
    #[allow(clippy::too_many_arguments)]
    pub fn generate<F: FnMut(&Place, Vec3, Vec3, ItemId)>(
        &self,
        sid: u32,
        range: std::ops::Range<u32>,
        part: Part,
        n: u64,
        place: &Place,
        rng: &mut Pcg64Mcg,
        f: &mut F,
    ) {
        if n == 0 {
            return;
        }
        let st = &self.structures[sid as usize];
        let node = self.scene.node(occult_core::NodeId(sid));
        if let Some(tree) = &st.tree {
            for _ in 0..n {
                let u = rng.random::<f64>();
                let pick = match part {
                    Part::Subtree(nd) => tree.sample(nd, u),
                    Part::Own(nd) => tree.sample_own(nd, u),
                    Part::Whole => tree.sample_all(u),
                };
                let Some(e) = pick else { return };
                let e = e as usize;
                match node.kind() {
                    NodeKind::Mesh(m) => self.points(m, e, 1, place, rng, f),
                    NodeKind::Group(g) => {
                        let inst = &g[e];
                        let child = place.enter(inst, node.item_offset(e), self.backface);
                        self.generate(inst.child.0, 0..0, Part::Whole, 1, &child, rng, f);
                    }
                }
            }
            return;
        }
        let whole = range.start == 0 && range.end as usize == st.octree.entries().len() && !st.alias.is_empty();
        self.descents(sid, (!whole).then_some(range), n, place, rng, f);
    }

    /// `n` samples of structure `sid` (`place` its space), each descending on its own: its
    /// position in the section `first` of the list by inverting the distribution list (a
    /// binary search of the prefix sums), or, with `first` `None`, in the whole structure by
    /// its alias table; below, an alias pick per level of instancing, in O(1), down to a
    /// triangle, whose random point (and, for back faces, edges) is then carried up the chain
    /// of instance transforms into `place`'s space, a point transform per level. Entering
    /// each instance instead (composing its matrices, [`Place::enter`]) cost a 4×4 matrix
    /// product per level and sample.
    ///
    /// The section's positions were once chosen together, as a multinomial split of sorted
    /// order statistics (`X₍ₖ₎ = X₍ₖ₊₁₎ · U^(1/k)`, one `powf` a sample) so that an instance
    /// chosen `k` times was entered once; a binary search a sample and no entering cost less
    /// (a sixth of a frame of `chessboard:n=10000000` went to the split).
    ///
    /// A descent is a chain of dependent loads (pick, entry, instance, child); [`LANES`]
    /// samples descend in lockstep, so that the loads of different samples overlap (15 % less
    /// CPU time than one after the other on `chessboard:n=10000000`).
    fn descents<F: FnMut(&Place, Vec3, Vec3, ItemId)>(
        &self,
        sid: u32,
        first: Option<std::ops::Range<u32>>,
        n: u64,
        place: &Place,
        rng: &mut Pcg64Mcg,
        f: &mut F,
    ) {
        let fresh = Descent {
            sid,
            item: place.base,
            depth: 0,
            leaf: NO_LEAF,
            chain: [&NO_LINK; CHAIN],
        };
        let mut lanes = [fresh; LANES];
        let mut left = n;
        while left > 0 {
            let m = left.min(LANES as u64) as usize;
            left -= m as u64;
            for d in &mut lanes[..m] {
                (d.sid, d.item, d.depth, d.leaf) = (sid, place.base, 0, NO_LEAF);
            }
            let mut live = (1u32 << m) - 1;
            while live != 0 {
                for (l, d) in lanes.iter_mut().enumerate().take(m) {
                    if live & (1 << l) != 0 && self.descend(d, &first, place, rng, f) {
                        live &= !(1 << l);
                    }
                }
            }
        }
    }

    /// One level of `d`'s descent ([`Sampler::descents`], `first` its section of the top
    /// level's list); true once its sample was passed to `f`.
    #[inline]
    fn descend<'s, F: FnMut(&Place, Vec3, Vec3, ItemId)>(
        &'s self,
        d: &mut Descent<'s>,
        first: &Option<std::ops::Range<u32>>,
        place: &Place,
        rng: &mut Pcg64Mcg,
        f: &mut F,
    ) -> bool {
        let st = &self.structures[d.sid as usize];
        if d.leaf != NO_LEAF {
            self.finish(st, d, d.leaf as usize, place, rng, f);
            return true;
        }
        let top = if d.depth == 0 { first.as_ref() } else { None };
        if top.is_none() && (st.tree.is_some() || st.alias.is_empty() || d.depth == CHAIN) {
            // Sampled otherwise (a distribution tree, an empty list) or a chain deeper than
            // the descent holds: the chain entered as before, and the structure sampled whole.
            let mut entered = place.clone();
            for link in &d.chain[..d.depth] {
                entered = entered.enter_by(&link.parent_from_child, link.item_offset, self.backface);
            }
            let len = st.octree.entries().len() as u32;
            self.generate(d.sid, 0..len, Part::Whole, 1, &entered, rng, f);
            return true;
        }
        let pos = match top {
            Some(range) => {
                let lo = st.octree.prefix(range.start);
                let area = st.octree.prefix(range.end) - lo;
                st.octree.locate(range.clone(), lo + rng.random::<f64>() * area)
            }
            None => st.alias.pick(rng.random::<u64>()),
        } as usize;
        if let Some(link) = st.links.get(pos) {
            d.chain[d.depth] = link;
            d.item += link.item_offset;
            d.depth += 1;
            d.sid = link.child;
            return false;
        }
        if st.soup.len() > FAR_SOUP {
            let corners = st.soup.as_ptr().wrapping_add(pos);
            occult_core::simd::prefetch(corners);
            occult_core::simd::prefetch(corners.wrapping_add(1).cast::<u8>().wrapping_sub(1));
            occult_core::simd::prefetch(st.octree.entries().as_ptr().wrapping_add(pos));
            d.leaf = pos as u32;
            return false;
        }
        self.finish(st, d, pos, place, rng, f);
        true
    }

    /// The end of `d`'s descent at list position `pos` of mesh structure `st`: a random point
    /// on the triangle (and, for back faces, its edges) carried up the chain into `place`'s
    /// space and passed to `f`.
    #[inline]
    fn finish<F: FnMut(&Place, Vec3, Vec3, ItemId)>(
        &self,
        st: &Structure,
        d: &Descent,
        pos: usize,
        place: &Place,
        rng: &mut Pcg64Mcg,
        f: &mut F,
    ) {
        let [a, b, c] = st.soup[pos];
        let e = st.octree.entries()[pos];
        let (r1, r2) = uniform_on_triangle(rng);
        let (mut e1, mut e2) = (b - a, c - a);
        let mut p = a + e1 * r1 + e2 * r2;
        for link in d.chain[..d.depth].iter().rev() {
            let t = &link.parent_from_child;
            p = t.transform_point3(p);
            if self.backface {
                e1 = t.transform_vector3(e1);
                e2 = t.transform_vector3(e2);
            }
        }
        // Carried up (with back faces only), the edges' cross product is the normal times the
        // chain's determinant: its sign restores the winding below `place`, as `place.sign`
        // does above it.
        f(place, p, e1.cross(e2), d.item + e as u64);
    }

    /// `count` uniform points on triangle `e` of `m` (§5.2), passed to `f`.
    #[inline]
    fn points<F: FnMut(&Place, Vec3, Vec3, ItemId)>(
        &self,
        m: &occult_core::Mesh,
        e: usize,
        count: u64,
        place: &Place,
        rng: &mut Pcg64Mcg,
        f: &mut F,
    ) {
        points_of(m.triangle_positions(e), e, count, place, rng, f);
    }

    /// Draws `count` fresh samples of `job` into `out` (§4.1 per pixel, §4.2 splats).
    pub fn draw_job(&self, job: &Job, count: u64, rng: &mut Pcg64Mcg, out: &mut Target<'_>, counts: &mut SampleCounts) {
        self.project_job(job, count, rng, counts, &mut |s| self.splat(s, out));
    }

    /// Draws cached samples (already quantized) of a box placed by `clip_from_structure`.
    pub fn draw_cached(
        &self,
        clip_from_structure: &Mat4,
        base: ItemId,
        samples: &[CachedSample],
        out: &mut Target<'_>,
        counts: &mut SampleCounts,
    ) {
        self.project_cached(clip_from_structure, base, samples, counts, &mut |s| self.splat(s, out));
    }

    /// Generates `count` fresh samples of `job` (§5.2, §5.3.3 back faces rejected) and passes
    /// those that project into the view to `emit`. The same generator state gives the same
    /// samples, which lets a second pass revisit them (§4.2 Gaussian reconstruction).
    pub fn project_job<E: FnMut(Projected)>(
        &self,
        job: &Job,
        count: u64,
        rng: &mut Pcg64Mcg,
        counts: &mut SampleCounts,
        emit: &mut E,
    ) {
        let place = Place::new(job, self.eye, self.backface);
        let backface = self.backface;
        let (width, height) = (self.width, self.height);
        let far_depth = self.far_depth;
        self.generate(
            job.structure,
            job.range.clone(),
            Part::of(job),
            count,
            &place,
            rng,
            &mut |pl, p, n, item| {
                counts.generated += 1;
                // §5.3.3: the eye taken into the mesh's space, the determinant's sign restoring
                // the winding.
                if backface && pl.sign * n.dot(pl.eye - p) <= 0.0 {
                    counts.backfacing += 1;
                    return;
                }
                if let Some(s) = project(&pl.clip_from_space, p, item, width, height, far_depth) {
                    counts.drawn += 1;
                    emit(s);
                }
            },
        );
    }

    /// Passes the cached samples that project into the view to `emit`.
    pub fn project_cached<E: FnMut(Projected)>(
        &self,
        clip_from_structure: &Mat4,
        base: ItemId,
        samples: &[CachedSample],
        counts: &mut SampleCounts,
        emit: &mut E,
    ) {
        for s in samples {
            if let Some(p) = project(
                clip_from_structure,
                s.position,
                base + s.item,
                self.width,
                self.height,
                self.far_depth,
            ) {
                counts.drawn += 1;
                emit(p);
            }
        }
    }

    /// §4.1/§4.2: writes a `d × d` splat of the sample's depth and item under the frame's
    /// (depth, item) rule.
    #[inline]
    fn splat(&self, s: Projected, out: &mut Target<'_>) {
        let px = (s.x as u32).min(out.width - 1);
        let py = (s.y as u32).min(out.height - 1);
        let (depth, item) = (s.depth, s.item);
        if self.splat == 1 {
            let i = (py * out.width + px) as usize;
            keep_fragment(&mut out.depth[i], &mut out.items[i], depth, item);
            return;
        }
        let d = self.splat;
        let x0 = px.saturating_sub((d - 1) / 2);
        let y0 = py.saturating_sub((d - 1) / 2);
        let x1 = (x0 + d).min(out.width);
        let y1 = (y0 + d).min(out.height);
        for y in y0..y1 {
            let row = (y * out.width) as usize;
            for x in x0..x1 {
                let i = row + x as usize;
                keep_fragment(&mut out.depth[i], &mut out.items[i], depth, item);
            }
        }
    }
}
