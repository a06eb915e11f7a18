//! Box selection (§5.3.2) with the large-triangle fallback (§7.1), walking the instancing DAG
//! (§7.3) with the crate's scene walk ([`crate::walk`]), so transforms and item ids are
//! composed as every renderer composes them. A structure instance is entered without a test of
//! the node's box ([`NodeTest::None`]): its octree roots, one per area class, are what is
//! tested, and only they count as tested boxes.

use occult_core::{Aabb, Affine3A, Containment, Frustum, ItemId, Mat4, Mesh, NodeKind, Scene, Vec3, Vec4, View};
use occult_raster::{Draw, DrawTriangles};

use crate::walk::{NodeAt, NodeTest, Placed, SceneWalk, Visitor};

use super::structure::{area_scale, Cone, Section, Structure};
use super::RzbOptions;

/// Per-view constants of the projection factor (§5.1).
#[derive(Clone, Copy, Debug)]
pub struct ViewConsts {
    /// Eye in world space.
    pub eye: Vec3,
    /// World to camera space.
    pub view_from_world: Mat4,
    /// Focal length in pixels: a unit length at view distance 1 spans this many pixels.
    pub focal_px: f64,
    /// Near plane distance.
    pub near: f32,
    /// `ln v` with `v` the number of splat-sized bins (§4.1.1, §4.2), at least 1.
    pub ln_v: f64,
    /// Splat side `d` in pixels.
    pub splat: u32,
    /// `1/cos α` at the frustum corners: the largest distortion factor (§5.1).
    pub max_inv_cos: f64,
}

impl ViewConsts {
    /// The constants of `view` for splat side `splat`.
    pub fn new(view: &View, splat: u32) -> Self {
        let sy = view.clip_from_view().y_axis.y as f64; // 1 / tan(fov_y / 2)
        let sx = view.clip_from_view().x_axis.x as f64;
        let focal_px = sy * view.height() as f64 * 0.5;
        let bins = (view.width() as f64 * view.height() as f64) / (splat as f64 * splat as f64);
        Self {
            eye: view.camera().eye,
            view_from_world: view.view_from_world(),
            focal_px,
            near: view.camera().near,
            ln_v: bins.ln().max(1.0),
            splat,
            max_inv_cos: (1.0 + 1.0 / (sx * sx) + 1.0 / (sy * sy)).sqrt(),
        }
    }
}

/// A selected box: a section of one structure's list, placed by `world_from_structure`.
#[derive(Clone, Debug)]
pub struct Job {
    /// The structure (= DAG node index).
    pub structure: u32,
    /// Its list positions.
    pub range: std::ops::Range<u32>,
    /// Its octree node.
    pub node: u32,
    /// Only the node's own entries.
    pub own: bool,
    /// The placement, composed from the root.
    pub world_from_structure: Affine3A,
    /// `view.clip_from_object(world_from_structure)`.
    pub clip_from_structure: Mat4,
    /// Item id of the structure instance's first triangle.
    pub base: ItemId,
    /// Bounds of the entries sampled (structure space): every sample lies in them.
    pub bounds: Aabb,
    /// Expected samples: area × maximum projection factor × ln v / d² (§5.3, §4.1.1).
    pub samples: f64,
    /// Nearest view distance of the box (clamped to the near plane).
    pub z_min: f32,
    /// Linear scale of `world_from_structure` (`|det|^(1/3)`).
    pub scale: f32,
}

impl Job {
    /// Identifies the box across frames (the cache's key, the root of its generators).
    pub fn key(&self) -> super::cache::BoxKey {
        (self.structure, self.base, self.range.start, self.range.end)
    }
}

/// The result of selection for one frame.
pub struct Selection<'a> {
    walk: SceneWalk<'a>,
    structures: &'a [Structure],
    consts: ViewConsts,
    eps: f64,
    large: Option<f64>,
    oversample: f64,
    /// Samples on back faces are rejected (§5.3.3): boxes whose orientation class faces away
    /// entirely are skipped (§5.3.4).
    backface: bool,
    /// Selected boxes.
    pub jobs: Vec<Job>,
    /// Triangles drawn by the z-buffer (§7.1).
    pub draws: Vec<Draw<'a>>,
    /// Octree nodes tested against the frustum.
    pub boxes_tested: u64,
    /// Of which outside.
    pub boxes_culled: u64,
    /// Structure instances entered.
    pub instances_visited: u64,
    /// Boxes handed to the z-buffer.
    pub boxes_zbuffer: u64,
    /// Mesh instances drawn whole by the z-buffer ([`RzbOptions::whole`]).
    pub instances_zbuffer: u64,
    /// [`RzbOptions::whole`].
    whole: bool,
    /// §5.3.4: boxes skipped wholesale because their orientation class faces away.
    pub boxes_backfacing: u64,
}

struct Place {
    /// The structure instance: its node, placement and first item.
    at: Placed,
    clip_from_structure: Mat4,
    frustum: Frustum,
    /// Rows 0, 1, 2 of `view_from_structure`.
    rows: [Vec4; 3],
    area_scale: f64,
    /// §5.3.4: the eye in structure space, when the placement is a similarity (angles kept).
    eye: Option<Vec3>,
    /// The placement mirrors (front faces are the other side).
    mirrored: bool,
}

/// §5.3.4: bounds of `cos γ` (γ between a normal of `cone` and the direction from a point of
/// box `b` to `eye`), all in structure space: (largest |cos γ| with both sides kept, largest
/// cos γ of front faces; ≤ 0 when every face looks away). `None` when unbounded (eye in the
/// box's sphere).
fn orientation_bound(cone: &Cone, b: &Aabb, eye: Vec3, mirrored: bool) -> Option<(f64, f64)> {
    let to_eye = eye - b.center();
    let dist = to_eye.length();
    let radius = b.half_extent().length();
    if dist.is_nan() || dist <= radius || cone.half_angle >= std::f32::consts::PI {
        return None;
    }
    let axis = if mirrored { -cone.axis } else { cone.axis };
    let theta = (to_eye.dot(axis) / dist).clamp(-1.0, 1.0).acos() as f64;
    let spread = cone.half_angle as f64 + (radius / dist).asin() as f64;
    let front = (theta - spread).max(0.0).cos();
    let back = (std::f64::consts::PI - theta - spread).max(0.0).cos();
    Some((front.max(back), front))
}

impl<'a> Selection<'a> {
    /// Selects the boxes of `view` with depth accuracy `eps`.
    pub fn run(
        scene: &'a Scene,
        structures: &'a [Structure],
        view: &'a View,
        opts: &RzbOptions,
        eps: f64,
        backface: bool,
    ) -> Self {
        let mut s = Self {
            walk: SceneWalk::new(scene, view),
            structures,
            consts: ViewConsts::new(view, opts.splat),
            eps,
            large: opts.large.then_some(opts.large_threshold),
            oversample: opts.oversample,
            backface,
            jobs: Vec::new(),
            draws: Vec::new(),
            boxes_tested: 0,
            boxes_culled: 0,
            instances_visited: 0,
            boxes_zbuffer: 0,
            instances_zbuffer: 0,
            whole: opts.whole,
            boxes_backfacing: 0,
        };
        Visitor::run(&mut s);
        s.boxes_tested = s.walk.stats.boxes_tested;
        s.boxes_culled = s.walk.stats.boxes_culled;
        s
    }
}

impl<'a> Visitor<'a> for Selection<'a> {
    const NODE_TEST: NodeTest = NodeTest::None;

    fn walk(&mut self) -> &mut SceneWalk<'a> {
        &mut self.walk
    }

    /// Enters a structure instance: its octree roots, one per area class.
    fn visit(&mut self, at: &NodeAt<'a>) {
        let id = at.place.id;
        let world_from_structure = at.place.world_from_node;
        let st = &self.structures[id.index()];
        if st.area <= 0.0 {
            return;
        }
        self.instances_visited += 1;
        let view_from_structure = self.consts.view_from_world * Mat4::from(world_from_structure);
        let t = view_from_structure.transpose();
        let place = Place {
            at: at.place,
            clip_from_structure: self.walk.view().clip_from_object(&world_from_structure),
            frustum: at.frustum,
            rows: [t.x_axis, t.y_axis, t.z_axis],
            area_scale: area_scale(&world_from_structure),
            eye: (!st.cones.is_empty() && is_similarity(&world_from_structure))
                .then(|| world_from_structure.inverse().transform_point3(self.consts.eye)),
            mirrored: world_from_structure.matrix3.determinant() < 0.0,
        };
        if self.dense_at_centre(&place, st) {
            return;
        }
        let at = (
            self.draws.len(),
            self.jobs.len(),
            self.boxes_zbuffer,
            self.boxes_backfacing,
        );
        for (class, root) in st.octree.roots().iter().enumerate() {
            if let Some(root) = root {
                self.node(&place, *root, st.cones.get(class));
            }
        }
        self.whole_if_mostly_drawn(&place, st, at);
    }
}

impl<'a> Selection<'a> {
    /// §5.1/§5.3: (nearest view distance clamped to the near plane, farthest, largest lateral
    /// extent across the view direction, samples) of the list positions `range` bounded by `b`;
    /// with an orientation class (§5.3.4) the samples carry its bound of the orientation factor,
    /// `None` when every face looks away and back faces are rejected.
    fn estimate(&self, p: &Place, b: &Aabb, sec: &Section, cone: Option<&Cone>) -> Option<(f64, f64, f64, f64)> {
        let c = b.center();
        let h = b.half_extent();
        let axis = |r: Vec4| (r.truncate().dot(c) + r.w, r.truncate().abs().dot(h));
        let (xc, dx) = axis(p.rows[0]);
        let (yc, dy) = axis(p.rows[1]);
        let (zc, dz) = axis(p.rows[2]);
        // The camera looks down -z: view distance is -z.
        let z_min = ((-zc - dz) as f64).max(self.consts.near as f64);
        let z_max = ((-zc + dz) as f64).max(z_min);
        let (xm, ym) = ((xc.abs() + dx) as f64, (yc.abs() + dy) as f64);
        let inv_cos = (1.0 + (xm * xm + ym * ym) / (z_min * z_min))
            .sqrt()
            .min(self.consts.max_inv_cos);
        let st = &self.structures[p.at.id.index()];
        let area = st.section_area(sec) * p.area_scale;
        let prj = self.consts.focal_px * self.consts.focal_px / (z_min * z_min) * inv_cos;
        let d2 = (self.consts.splat * self.consts.splat) as f64;
        let mut samples = area * prj * self.consts.ln_v / d2 * self.oversample;
        if let (Some(cone), Some(eye)) = (cone, p.eye) {
            if let Some((both, front)) = orientation_bound(cone, b, eye, p.mirrored) {
                if self.backface {
                    if front <= 0.0 {
                        return None;
                    }
                    samples *= front;
                } else {
                    samples *= both;
                }
            }
        }
        Some((z_min, z_max, 2.0 * dx.max(dy) as f64, samples))
    }

    /// [`RzbOptions::whole`], before any descent: a mesh instance wholly beyond the near plane
    /// whose triangles would get on average more than twice the threshold of samples each at
    /// the view distance of its box's centre is drawn whole at once (its octrees' descent is
    /// most of a frame's selection, and §7.1 would draw most of it). True when drawn (or
    /// outside the view).
    fn dense_at_centre(&mut self, p: &Place, st: &Structure) -> bool {
        let Some(threshold) = self.large.filter(|_| self.whole && st.tree.is_none()) else {
            return false;
        };
        let NodeKind::Mesh(mesh) = self.walk.scene().node(p.at.id).kind() else {
            return false;
        };
        let bounds = st
            .octree
            .roots()
            .iter()
            .flatten()
            .fold(Aabb::EMPTY, |b, &r| b.union(st.octree.nodes()[r as usize].bounds));
        if bounds.is_empty() || mesh.triangle_count() == 0 {
            return false;
        }
        // Only a box wholly beyond the near plane: one that holds the eye (a terrain, a
        // building walked through) is descended, whatever its centre's distance.
        let r = p.rows[2];
        let (zc, dz) = (
            -(r.truncate().dot(bounds.center()) + r.w),
            r.truncate().abs().dot(bounds.half_extent()),
        );
        if zc - dz <= self.consts.near {
            return false;
        }
        let z = zc as f64;
        let prj = self.consts.focal_px * self.consts.focal_px / (z * z);
        let d2 = (self.consts.splat * self.consts.splat) as f64;
        let samples = st.area * p.area_scale * prj * self.consts.ln_v / d2 * self.oversample;
        if samples / (mesh.triangle_count() as f64) <= 2.0 * threshold {
            return false;
        }
        // Not a counted box test (the octree roots are this renderer's boxes).
        if p.frustum.classify_aabb(&bounds) != Containment::Outside {
            self.draw_whole(p, mesh);
        }
        true
    }

    /// One draw of the whole mesh of instance `p`, counted in `instances_zbuffer`.
    fn draw_whole(&mut self, p: &Place, mesh: &'a Mesh) {
        self.instances_zbuffer += 1;
        self.draws.push(Draw {
            mesh,
            triangles: DrawTriangles::All,
            clip_from_object: p.clip_from_structure,
            first_item: p.at.first_item,
        });
    }

    /// [`RzbOptions::whole`] (not in the paper): once a mesh instance's octrees were
    /// descended, when §7.1 drew more than half of its triangles (the draws and jobs after
    /// those counted in `at` are this instance's: a mesh's descent enters no instance), they
    /// and its sampled boxes give way to one draw of the whole mesh: each vertex projected
    /// once instead of a list per leaf, and the rest drawn exactly instead of sampled; the
    /// counts of its boxes drawn and skipped as back-facing go back to `at`'s. Only static
    /// structures (a removed entry would be drawn).
    fn whole_if_mostly_drawn(&mut self, p: &Place, st: &Structure, at: (usize, usize, u64, u64)) {
        let (draws_at, jobs_at, zbuffer_at, backfacing_at) = at;
        if !self.whole || st.tree.is_some() || self.draws.len() == draws_at {
            return;
        }
        let NodeKind::Mesh(mesh) = self.walk.scene().node(p.at.id).kind() else {
            return;
        };
        let drawn: usize = self.draws[draws_at..]
            .iter()
            .map(|d| match d.triangles {
                DrawTriangles::List(l) => l.len(),
                _ => mesh.triangle_count(),
            })
            .sum();
        if drawn * 2 <= mesh.triangle_count() {
            return;
        }
        self.draws.truncate(draws_at);
        self.jobs.truncate(jobs_at);
        self.boxes_zbuffer = zbuffer_at;
        self.boxes_backfacing = backfacing_at;
        self.draw_whole(p, mesh);
    }

    /// The counted frustum test: false when `b` is outside.
    fn test(&mut self, p: &Place, b: &Aabb) -> bool {
        self.walk.test(&p.frustum, b) != Containment::Outside
    }

    /// §5.3.2: select node `n` when its depth-factor ratio `(z_max / z_min)²` is within ε (and,
    /// with §7.1, its triangles are small enough to sample); otherwise descend.
    fn node(&mut self, p: &Place, n: u32, cone: Option<&Cone>) {
        let st = &self.structures[p.at.id.index()];
        let node = st.octree.nodes()[n as usize];
        if !self.test(p, &node.bounds) {
            return;
        }
        let whole = Section {
            node: n,
            own: false,
            range: node.section(),
        };
        let Some((z_min, z_max, lateral, samples)) = self.estimate(p, &node.bounds, &whole, cone) else {
            self.boxes_backfacing += 1;
            return;
        };
        let ratio = (z_max / z_min).powi(2);
        // Deviation: the paper's boxes are the octree's cubes, whose extent across the view
        // the depth test bounds as well (§5.3.2: the selected boxes exceed the frustum's cross
        // section only by a constant). Ours are tight bounds, which for a row of instances
        // (`forest`'s replication rows, 682 km × 9 km) can be a slab seen edge-on: a small depth
        // ratio, yet up to 40 times wider than the frustum, so that 90 % of its samples fall outside
        // the view. A box is therefore selected only when its lateral extent is also within
        // what a cube passing the depth test could have (`√3 · (√ε − 1) · z_min`: a cube's
        // view-space width is at most √3 times its depth extent), else it is split further.
        let lateral_ok = lateral <= 3f64.sqrt() * (self.eps.sqrt() - 1.0) * z_min;
        let per_item = samples / st.section_items(&whole).max(1) as f64;
        let too_dense = self.large.is_some_and(|t| per_item > t);
        if ratio <= self.eps && lateral_ok && !too_dense {
            self.select(p, whole, node.bounds, samples, z_min);
        } else if node.is_leaf() {
            self.part(p, whole, node.bounds, false, cone);
        } else {
            for c in node.children() {
                self.node(p, c, cone);
            }
            if node.own_first < node.end {
                let own = Section {
                    node: n,
                    own: true,
                    range: node.own(),
                };
                self.part(p, own, node.own_bounds, true, cone);
            }
        }
    }

    /// List positions that cannot be split spatially (a leaf, or a node's own entries).
    /// Triangles: sampled at the bound's nearest distance, or drawn by the z-buffer when they
    /// would get more than the threshold of samples each (§7.1). Instances: each entered.
    fn part(&mut self, p: &Place, sec: Section, bounds: Aabb, test: bool, cone: Option<&Cone>) {
        if test && !self.test(p, &bounds) {
            return;
        }
        let st = &self.structures[p.at.id.index()];
        let node = self.walk.scene().node(p.at.id);
        match node.kind() {
            NodeKind::Mesh(mesh) => {
                let Some((z_min, _, _, samples)) = self.estimate(p, &bounds, &sec, cone) else {
                    self.boxes_backfacing += 1;
                    return;
                };
                let items = st.section_items(&sec);
                if items == 0 {
                    return;
                }
                let per_item = samples / items as f64;
                if self.large.is_some_and(|t| per_item > t) {
                    self.boxes_zbuffer += 1;
                    // A leaf's section is its own list; with a distribution tree, the entries
                    // present now (sorted by id, as the static list).
                    let list = match &st.tree {
                        Some(t) => t.own(sec.node),
                        None => &st.octree.entries()[sec.range.start as usize..sec.range.end as usize],
                    };
                    self.draws.push(Draw {
                        mesh,
                        triangles: DrawTriangles::List(list),
                        clip_from_object: p.clip_from_structure,
                        first_item: p.at.first_item,
                    });
                } else {
                    self.select(p, sec, bounds, samples, z_min);
                }
            }
            NodeKind::Group(_) => {
                let present: &[u32] = match &st.tree {
                    Some(t) => t.own(sec.node),
                    None => &st.octree.entries()[sec.range.start as usize..sec.range.end as usize],
                };
                for &e in present {
                    self.enter(p.at.child_of(node, e as usize), false);
                }
            }
        }
    }

    fn select(&mut self, p: &Place, sec: Section, bounds: Aabb, samples: f64, z_min: f64) {
        if samples <= 0.0 {
            return;
        }
        self.jobs.push(Job {
            structure: p.at.id.0,
            range: sec.range,
            node: sec.node,
            own: sec.own,
            world_from_structure: p.at.world_from_node,
            clip_from_structure: p.clip_from_structure,
            base: p.at.first_item,
            bounds,
            samples,
            z_min: z_min as f32,
            scale: p.area_scale.sqrt() as f32,
        });
    }
}

/// True when `t`'s linear part is a rotation (or reflection) times a uniform scale, so angles
/// between directions are kept.
fn is_similarity(t: &Affine3A) -> bool {
    let m = t.matrix3;
    let (x, y, z) = (Vec3::from(m.x_axis), Vec3::from(m.y_axis), Vec3::from(m.z_axis));
    let l = x.length_squared();
    let tol = 1e-4 * l;
    l > 0.0
        && (y.length_squared() - l).abs() <= tol
        && (z.length_squared() - l).abs() <= tol
        && x.dot(y).abs() <= tol
        && y.dot(z).abs() <= tol
        && x.dot(z).abs() <= tol
}
