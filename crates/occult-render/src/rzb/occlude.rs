//! `occlude=on` (an addition to the paper): the test that tells a box whose samples would all
//! lose the depth test against the frame drawn so far, the batches the boxes are drawn in
//! (nearest first), and the split of a box that is not hidden into parts tested in turn.

use occult_core::{Aabb, Mat4, Scene, View};
use occult_raster::{Frame, PixelRect, PyramidCounts, PyramidTest, ZPyramid};
use rayon::prelude::*;

use super::structure::{self, Structure};
use super::{select, Recon, RzbOptions};

/// Relative depth margin of [`occluded`]: a sample's depth is computed through its own chain
/// of instance transforms, the box's corners through the composed matrix.
const OCCLUDE_DEPTH_MARGIN: f32 = 1e-4;
/// Pixel margin of [`occluded`], for the same rounding on screen.
const OCCLUDE_PIXEL_MARGIN: f32 = 0.5;

/// `occlude=on`: true when no sample of `job` can change `frame` (or, with `gauss`, the
/// Gaussian pass's colors): every pixel a sample in its bounds (grown by `grow`, structure
/// space, for quantized cached sets) may write holds a depth nearer than the box's nearest
/// corner, as far as `pyramid` (up to date with `frame`) shows. A sample writes the pixel its
/// projection falls in, or a `splat`-sided square around it; the Gaussian pass writes within
/// `reach` pixels and keeps samples within `keep` of a pixel's view distance, so its depth
/// bound is that much nearer. A box reaching the near plane is never hidden.
///
/// Skipping such a box leaves the frame as it would have been: its samples would all have
/// lost the depth test there, and depth only grows while a frame is drawn. Other boxes'
/// samples do not change (each box has its own generator); a box that is [`split`] is
/// sampled by its parts' generators instead, each at the density its own distance asks.
pub(super) fn occluded(
    pyramid: &ZPyramid,
    frame: &Frame,
    clip_from_structure: &Mat4,
    b: &Aabb,
    reach: Reach,
    counts: &mut PyramidCounts,
) -> bool {
    let mut nearest = f32::NEG_INFINITY;
    let (mut x0, mut x1, mut y0, mut y1) = (f32::INFINITY, f32::NEG_INFINITY, f32::INFINITY, f32::NEG_INFINITY);
    let (w, h) = (frame.width() as f32, frame.height() as f32);
    for p in b.corners() {
        let c = *clip_from_structure * p.extend(1.0);
        if !c.is_finite() || c.w <= 0.0 || c.z * (1.0 + OCCLUDE_DEPTH_MARGIN) >= c.w {
            return false;
        }
        let inv_w = 1.0 / c.w;
        nearest = nearest.max(c.z * inv_w);
        let x = (c.x * inv_w * 0.5 + 0.5) * w;
        let y = (0.5 - c.y * inv_w * 0.5) * h;
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    // Samples outside the view are dropped.
    if x1 + OCCLUDE_PIXEL_MARGIN < 0.0
        || y1 + OCCLUDE_PIXEL_MARGIN < 0.0
        || x0 - OCCLUDE_PIXEL_MARGIN > w
        || y0 - OCCLUDE_PIXEL_MARGIN > h
    {
        return true;
    }
    // The pixels samples fall in (clamped as the splat clamps them), grown by the splat.
    let pixel = |v: f32, n: f32| (v.clamp(0.0, n) as i64).min(n as i64 - 1);
    let (before, after) = (reach.before as i64, reach.after as i64);
    let span = |lo: f32, hi: f32, n: f32| {
        let a = pixel(lo - OCCLUDE_PIXEL_MARGIN, n) - before;
        let b = pixel(hi + OCCLUDE_PIXEL_MARGIN, n) + after + 1;
        (a.clamp(0, n as i64) as u32, b.clamp(0, n as i64) as u32)
    };
    let (rx0, rx1) = span(x0, x1, w);
    let (ry0, ry1) = span(y0, y1, h);
    let rect = PixelRect {
        x0: rx0,
        y0: ry0,
        x1: rx1,
        y1: ry1,
    };
    let how = PyramidTest {
        global: true,
        hierarchical: true,
    };
    pyramid.occludes(
        frame,
        rect,
        nearest * (1.0 + OCCLUDE_DEPTH_MARGIN) * reach.depth_factor,
        how,
        counts,
    )
}

/// How far a sample's effect reaches from the pixel it falls in: `before` pixels left and up,
/// `after` right and down, and how much nearer than the sample a pixel's depth must be
/// (a factor ≥ 1 on reversed depth) for the sample to leave it unchanged.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Reach {
    before: u32,
    after: u32,
    depth_factor: f32,
}

impl Reach {
    /// A `splat`-sided square (§4.2), or with the Gaussian pass a `sigma` filter's 3σ support
    /// and its visibility tolerance.
    pub(super) fn of(opts: &RzbOptions) -> Self {
        let d = opts.splat;
        let splat = Self {
            before: (d - 1) / 2,
            after: d - 1 - (d - 1) / 2,
            depth_factor: 1.0,
        };
        match opts.recon {
            Recon::Nearest => splat,
            Recon::Gauss => {
                let r = (3.0 * opts.sigma).ceil() as u32 + 1;
                Self {
                    before: splat.before.max(r),
                    after: splat.after.max(r),
                    depth_factor: 1.0 + opts.gauss_tolerance,
                }
            }
        }
    }
}

/// `occlude=on`: expected samples of the first batch, per pixel of the frame ...
pub(super) const FIRST_BATCH_PER_PIXEL: f64 = 0.5;
/// ... and the factor from a batch to the next.
const BATCH_GROWTH: f64 = 1.5;

/// `occlude=on`: the parts of a selected box that failed its occlusion test, when it is the
/// subtree of an inner octree node with at least `min_samples` expected samples: each child's
/// subtree and the node's own entries, with their tight bounds, so a part hidden behind what
/// is drawn can be skipped. A part takes its share of the box's samples by area, times
/// [`part_density`]: the density §4.1.1 asks at the part's own nearest distance, which is
/// never above the box's (a part of the box passes the box's depth test; its own nearest
/// point is at least as far). `None` for a box that cannot be split (a leaf, a node's own
/// entries, a distribution tree's section).
pub(super) fn split(
    scene: &Scene,
    view: &View,
    structures: &[Structure],
    job: &select::Job,
    min_samples: f64,
) -> Option<Vec<select::Job>> {
    if min_samples <= 0.0 || job.samples < min_samples {
        return None;
    }
    let st = &structures[job.structure as usize];
    if st.tree.is_some() {
        return None;
    }
    let node = st.octree.nodes()[job.node as usize];
    if job.own || node.is_leaf() {
        return enter_instances(scene, view, structures, job);
    }
    if node.section() != job.range {
        return None;
    }
    let area = |sec: &structure::Section| st.section_area(sec);
    let whole = area(&structure::Section {
        node: job.node,
        own: false,
        range: job.range.clone(),
    });
    if whole.is_nan() || whole <= 0.0 {
        return None;
    }
    let mut parts = Vec::new();
    let mut part = |sec: structure::Section, bounds: Aabb| {
        let a = area(&sec);
        if a > 0.0 && !bounds.is_empty() {
            let (z, dens) = part_density(&job.clip_from_structure, &bounds, job.z_min, view.camera().near);
            parts.push(select::Job {
                node: sec.node,
                own: sec.own,
                range: sec.range,
                bounds,
                samples: job.samples * a / whole * dens,
                z_min: z,
                ..job.clone()
            });
        }
    };
    for c in node.children() {
        let child = st.octree.nodes()[c as usize];
        part(
            structure::Section {
                node: c,
                own: false,
                range: child.section(),
            },
            child.bounds,
        );
    }
    if node.own_first < node.end {
        part(
            structure::Section {
                node: job.node,
                own: true,
                range: node.own(),
            },
            node.own_bounds,
        );
    }
    Some(parts)
}

/// `occlude=on`: a part `b` (placed by `clip_from_structure`) of a box whose nearest view
/// distance is `z_box`: its own nearest view distance (clip `w`, at least `z_box` and the near
/// plane) and the factor on the box's sample density that gives the part the density §4.1.1
/// asks at that distance, `(z_box / z)²` (never above 1).
fn part_density(clip_from_structure: &Mat4, b: &Aabb, z_box: f32, near: f32) -> (f32, f64) {
    let r = clip_from_structure.row(3);
    let (c, h) = (b.center(), b.half_extent());
    let z = (r.truncate().dot(c) + r.w - r.truncate().abs().dot(h))
        .max(near)
        .max(z_box);
    (z, (z_box as f64 / z as f64).powi(2))
}

/// `occlude=on`: the parts of the boxes split in a batch, each tested against the pyramid
/// of the frame drawn before the batch and split again while it is large and not hidden.
pub(super) struct PartTest<'a> {
    pub(super) scene: &'a Scene,
    pub(super) view: &'a View,
    pub(super) structures: &'a [Structure],
    pub(super) pyramid: &'a ZPyramid,
    pub(super) frame: &'a Frame,
    pub(super) reach: Reach,
    pub(super) min_samples: f64,
    /// The frame's sample cap factor (the hidden samples are counted with it).
    pub(super) cap: f64,
}

/// What [`PartTest`] found: the parts to sample, and the counts of the hidden and the split.
#[derive(Default)]
pub(super) struct Resolved {
    pub(super) accepted: Vec<select::Job>,
    pub(super) hidden: u64,
    pub(super) hidden_samples: f64,
    pub(super) splits: u64,
}

impl PartTest<'_> {
    /// Every part in `parts` resolved, in parallel over them: one [`Resolved`] each, in their
    /// order (the frame does not depend on it).
    pub(super) fn resolve_all(&self, parts: Vec<select::Job>) -> Vec<Resolved> {
        parts
            .into_par_iter()
            .map(|part| {
                let mut r = Resolved::default();
                self.resolve(part, &mut r);
                r
            })
            .collect()
    }

    fn resolve(&self, part: select::Job, out: &mut Resolved) {
        let mut counts = PyramidCounts::default();
        if occluded(
            self.pyramid,
            self.frame,
            &part.clip_from_structure,
            &part.bounds,
            self.reach,
            &mut counts,
        ) {
            out.hidden += 1;
            out.hidden_samples += part.samples * self.cap;
            return;
        }
        match split(self.scene, self.view, self.structures, &part, self.min_samples) {
            Some(parts) => {
                out.splits += 1;
                for p in parts {
                    self.resolve(p, out);
                }
            }
            None => out.accepted.push(part),
        }
    }
}

/// [`split`] of a box that holds instances (a group's leaf or a node's own entries): each
/// instance entered, as one box per orientation class of its child's structure, placed and
/// numbered as the scene walk places it, with the instance's share of the box's samples by
/// area times [`part_density`]. `None` for a box of triangles.
fn enter_instances(
    scene: &Scene,
    view: &View,
    structures: &[Structure],
    job: &select::Job,
) -> Option<Vec<select::Job>> {
    let st = &structures[job.structure as usize];
    let group = scene.node(occult_core::NodeId(job.structure));
    if !matches!(group.kind(), occult_core::NodeKind::Group(_)) {
        return None;
    }
    let whole = st.section_area(&structure::Section {
        node: job.node,
        own: job.own,
        range: job.range.clone(),
    });
    if whole.is_nan() || whole <= 0.0 {
        return None;
    }
    let at = crate::walk::Placed {
        id: occult_core::NodeId(job.structure),
        world_from_node: job.world_from_structure,
        first_item: job.base,
    };
    let mut parts = Vec::new();
    for &e in &st.octree.entries()[job.range.start as usize..job.range.end as usize] {
        let inst = &group.instances()[e as usize];
        let child = at.child_of(group, e as usize);
        let cs = &structures[child.id.index()];
        let share = structure::area_scale(&inst.parent_from_child) / whole;
        let clip_from_structure = view.clip_from_object(&child.world_from_node);
        let scale = structure::area_scale(&child.world_from_node).sqrt() as f32;
        for root in cs.octree.roots().iter().flatten() {
            let n = cs.octree.nodes()[*root as usize];

            let sec = structure::Section {
                node: *root,
                own: false,
                range: n.section(),
            };
            let a = cs.section_area(&sec) * share;
            if a > 0.0 && !n.bounds.is_empty() {
                let (z, dens) = part_density(&clip_from_structure, &n.bounds, job.z_min, view.camera().near);
                parts.push(select::Job {
                    structure: child.id.0,
                    range: sec.range,
                    node: *root,
                    own: false,
                    world_from_structure: child.world_from_node,
                    clip_from_structure,
                    base: child.first_item,
                    bounds: n.bounds,
                    samples: job.samples * a * dens,
                    z_min: z,
                    scale,
                });
            }
        }
    }
    Some(parts)
}

/// `occlude=on`: the boxes in `order` (nearest first) cut into batches of doubling expected
/// samples (`samples` of a box), the first of about four samples per pixel of the frame's
/// `pixels`: each batch is tested against the depth of the ones before, so the first holds
/// the nearest surfaces and later ones are large enough that the pyramid's rebuild and the
/// threads' merge stay small beside them.
pub(super) fn occlusion_batches(
    order: &[usize],
    samples: impl Fn(usize) -> f64,
    pixels: f64,
) -> Vec<std::ops::Range<usize>> {
    let mut batches = Vec::new();
    let (mut start, mut sum, mut target) = (0, 0.0, FIRST_BATCH_PER_PIXEL * pixels);
    for (i, &k) in order.iter().enumerate() {
        sum += samples(k);
        if sum >= target {
            batches.push(start..i + 1);
            start = i + 1;
            sum = 0.0;
            target *= BATCH_GROWTH;
        }
    }
    if start < order.len() || batches.is_empty() {
        batches.push(start..order.len());
    }
    batches
}

#[cfg(test)]
mod tests {
    use super::*;
    use occult_core::{Vec3, Vec4};

    #[test]
    fn a_part_is_sampled_at_its_own_distance_never_above_its_box() {
        // Clip w is the view distance (the camera at the origin, looking down -z), as in the
        // reversed-z projection: clip = (x, y, near, -z).
        let clip = Mat4::from_cols(
            Vec4::X,
            Vec4::Y,
            Vec4::new(0.0, 0.0, 0.0, -1.0),
            Vec4::new(0.0, 0.0, 0.5, 0.0),
        );
        let slab = |near: f32, far: f32| Aabb::new(Vec3::new(-1.0, -1.0, -far), Vec3::new(1.0, 1.0, -near));
        let (z, f) = part_density(&clip, &slab(20.0, 22.0), 10.0, 0.5);
        assert!((z - 20.0).abs() < 1e-3 && (f - 0.25).abs() < 1e-3, "({z}, {f})");
        // As near as the box, or reaching behind the eye: the box's distance and density.
        for b in [slab(10.0, 12.0), slab(-5.0, 12.0)] {
            let (z, f) = part_density(&clip, &b, 10.0, 0.5);
            assert!(z == 10.0 && f == 1.0, "({z}, {f})");
        }
    }
}
