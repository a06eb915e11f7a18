//! Shadow volumes of a spot light, culled and clamped with min/max litmaps and N-buffers
//! (Décoret 2005 §3.3, §4.4).
//!
//! # References
//! Décoret, *N-Buffers for efficient depth map query*, 2005 (`papers/n-buffers-decoret-2005.txt`):
//! - §3.3 "Generation of litmaps": the observer's visible surface is reprojected into the
//!   light's view; per lexel, the *min litmap* keeps the nearest and the *max litmap* the
//!   farthest visible point's distance to the light.
//! - §3.3 "Finding extents": an N-buffer over each litmap (nearest and farthest variants);
//!   each shadow caster's light-space box gives `z_min` (nearest visible point) and `z_max`
//!   (farthest) with four lookups each.
//! - §3.3 "Shadowing": a caster with `z_max < z_min` is culled (nothing visible in its box);
//!   otherwise its volume is clamped between the two planes perpendicular to the light
//!   direction at `z_min` and `z_max`, and capped.
//! - §4.4: the fill rate (stencil fragments) with and without clamping.
//!
//! # The volumes
//! A *caster* is a mesh instance of the scene, or a leaf of a BVH over a large mesh's triangles
//! (meshes above `leaf` triangles, so a terrain is many casters). Its volume is the union of
//! the per-triangle volumes of its *lit* triangles (front face toward the light, every corner
//! beyond the light's near plane): each is the region behind the triangle from the light. The
//! side faces of edges shared by two lit triangles of the caster cancel (edges matched by
//! their corners' positions, each direction counting ±1), so only silhouette and boundary
//! edges are extruded; the count a pixel receives is the same as with per-triangle volumes,
//! and open meshes (terrain, single walls) need no special case. The stencil pass counts with
//! the z-fail rule ([`occult_raster::StencilDraw`]); a visible point is **shadowed** when it lies
//! inside the light's frustum (a square spot of the light's cone angle) and its count is not 0.
//!
//! - **Unclamped**: front caps are the lit triangles themselves, sides run from the caster to
//!   the plane at distance `D` (beyond every point of the scene), where the back cap lies.
//!   Each side quad is cut where the clamped volume's sides start and end (the litmaps and
//!   N-buffers are built in both modes for that): the same surface, in more triangles.
//! - **Clamped**: the caster's box in light space is looked up in both N-buffers; culled when
//!   its box holds no visible point (`z_max < z_min`, the paper's test) or when every visible
//!   point of the box is nearer the light than the caster's nearest lit corner (an extra test:
//!   such points cannot lie behind it). Otherwise the back cap moves to
//!   `max(z_max, caster's farthest corner)·(1 + ε)` and, when the whole caster lies nearer the
//!   light than `z_min·(1 − ε)`, the front cap moves onto that plane (the paper's cases (b),
//!   (d) of Fig. 5); `ε` = [`CLAMP_MARGIN`].
//!
//! Shadows are identical with and without clamping (tested on `city` and `terrain` views):
//! every visible point inside a caster's volume lies in its box and between the two planes, so
//! its count does not change; the caps moved to the planes stay `ε` away from every visible
//! point, and the side faces keep their exact planes (plane depth, see
//! [`occult_raster::StencilFaces::Planes`]) so a shadow boundary cannot move by rounding.
//! Between the two planes, where every visible point lies, both modes draw the very same side
//! triangles (same snapped corners): a visible point exactly on a shadow's boundary is
//! classified alike. (With one quad from the caster to `D`, the far corners' snapping moved
//! the screen edges along the light rays, and one terrain pixel flipped: tested.)
//!
//! # Deviations
//! - Software throughout: the litmaps are built by reprojecting the observer's depth buffer
//!   pixel by pixel (each visible point into the lexel its light ray crosses), not by drawing
//!   the scene in the light's view with a depth comparison against the observer's map (Fig. 6);
//!   the litmaps then hold exactly the points whose shadow flag the stencil decides.
//! - Clamping is decided per caster, not per silhouette edge: the front cap moves to the
//!   `z_min` plane only when the whole caster is nearer the light (the paper: an edge farther
//!   than the plane is not projected onto it). The volume stays closed in every case.
//! - Per-triangle volumes with shared sides cancelled instead of a silhouette of a closed
//!   mesh: the scenes' meshes are not all closed.
//! - The unclamped volumes' sides are cut at the clamping planes (see above), so the
//!   unclamped run builds the litmaps and N-buffers too; its fill is unchanged.
//! - A margin `ε` around the planes, and one lexel around each box, absorb the rounding of the
//!   reprojection; the N-buffers' 16-bit keys round outward by themselves.
//! - Cost of a caster's box: its world box's 8 corners projected (the paper's "vertices of a
//!   bounding volume"); a box reaching behind the light's near plane covers the whole map.
//!
//! # Cost
//! Per frame: one pass over the observer's pixels, two N-buffer builds at the litmap
//! resolution, 8 lookups per caster, a pass over every lit triangle of every caster (silhouette
//! extraction) and the stencil fill. Not meant for scenes above [`MAX_SHADOW_TRIANGLES`]
//! triangle instances (every caster is visited each frame).

// Negated comparisons are deliberate: they send NaN down the safe branch.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::collections::HashMap;
use std::time::Instant;

use occult_core::glam::{DMat4, DVec3, DVec4};
use occult_core::{Aabb, Affine3A, Camera, ItemId, Mat4, Mesh, Scene, Vec3, View};
use occult_raster::{
    Draw, DrawTriangles, Extremum, Frame, NBuffer, PixelRect, Rasterizer, StencilBuffer, StencilCounts, StencilDraw,
    StencilFaces, CLEAR_DEPTH,
};
use occult_spatial::Bvh;
use rayon::prelude::*;

use crate::{RenderError, Result};

/// Largest number of triangle instances [`ShadowCasters::new`] accepts.
pub const MAX_SHADOW_TRIANGLES: u64 = 1 << 26;
/// Relative margin between a clamping plane and the nearest (farthest) visible point.
pub const CLAMP_MARGIN: f64 = 1e-3;
/// Largest litmap side in lexels.
pub const MAX_LITMAP: u32 = 4096;

/// A spot light: a point light whose light leaves through a square cone (the light's view
/// frustum) of full angle `cone_deg` around the direction to `target`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpotLight {
    /// Position, world space.
    pub position: Vec3,
    /// A point on the light's axis, world space.
    pub target: Vec3,
    /// Full cone angle in degrees, in (0, 170].
    pub cone_deg: f32,
    /// Litmap side in lexels (1..=[`MAX_LITMAP`]).
    pub resolution: u32,
}

impl SpotLight {
    /// A light above and beside `bounds`, aimed at its centre, with a cone that holds its
    /// bounding sphere: long shadows over the whole scene.
    pub fn for_bounds(bounds: &Aabb) -> Self {
        let c = bounds.center();
        let s = bounds.size().max_element().max(1e-3);
        let position = c + Vec3::new(-0.55 * s, 0.45 * s + bounds.size().y, -0.35 * s);
        let r = bounds.size().length() * 0.5;
        let dist = (position - c).length();
        let half = (r / dist).clamp(0.0, 0.99).asin().to_degrees();
        Self {
            position,
            target: c,
            cone_deg: (2.0 * half).clamp(1.0, 170.0),
            resolution: 512,
        }
    }

    /// The light's view: eye at the light, looking at the target, square, `resolution` lexels.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for non-finite values, a cone outside (0°, 170°], a
    /// resolution outside 1..=[`MAX_LITMAP`], or the target at the light.
    pub fn view(&self) -> Result<View> {
        let bad = |why: String| Err(RenderError::BadParameter(format!("shadows: {why}")));
        if !(self.position.is_finite() && self.target.is_finite()) {
            return bad("light position or target is not finite".into());
        }
        if !(self.cone_deg > 0.0 && self.cone_deg <= 170.0) {
            return bad(format!("cone angle {}° is not in (0°, 170°]", self.cone_deg));
        }
        if !(1..=MAX_LITMAP).contains(&self.resolution) {
            return bad(format!(
                "litmap resolution {} is not in 1..={MAX_LITMAP}",
                self.resolution
            ));
        }
        let axis = self.target - self.position;
        if !(axis.length() > 0.0) {
            return bad("light target equals its position".into());
        }
        let dir = axis.normalize();
        let up = if dir.y.abs() > 0.99 { Vec3::Z } else { Vec3::Y };
        let camera = Camera {
            eye: self.position,
            target: self.target,
            up,
            fov_y_deg: self.cone_deg,
            near: (axis.length() * 1e-4).max(1e-4),
            far: f32::MAX / 4.0,
        };
        View::new(camera, self.resolution, self.resolution)
            .map_err(|e| RenderError::BadParameter(format!("shadows: light view: {e}")))
    }
}

/// One caster: a mesh instance or a leaf of its mesh's BVH.
#[derive(Clone, Debug)]
struct Caster {
    /// Index into [`ShadowCasters::instances`].
    instance: u32,
    /// Range into [`ShadowCasters::leaf_triangles`] of the mesh, or `None` for all triangles.
    leaf: Option<(u32, std::ops::Range<u32>)>,
    /// World box.
    bounds: Aabb,
}

/// A mesh instance of the scene.
#[derive(Clone, Debug)]
struct InstanceRef {
    mesh: occult_core::NodeId,
    world_from_object: Affine3A,
    first_item: ItemId,
}

/// The shadow casters of a scene: built once, used for any view and light.
pub struct ShadowCasters {
    scene: std::sync::Arc<Scene>,
    instances: Vec<InstanceRef>,
    casters: Vec<Caster>,
    /// Per BVH-split mesh: its triangles in leaf order.
    leaf_triangles: Vec<Vec<u32>>,
}

/// Which of the two algorithms [`ShadowCasters::shadows`] runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Clamping {
    /// Every caster's volume from the caster to beyond the scene.
    Off,
    /// Culled and clamped with the litmaps' N-buffers (§3.3).
    On,
}

/// A pixel's state after the stencil pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Shade {
    /// No visible surface.
    Sky = 0,
    /// A visible point outside the light's frustum.
    OutsideLight = 1,
    /// Inside the frustum, count 0.
    Lit = 2,
    /// Inside the frustum, count not 0.
    Shadowed = 3,
}

/// Counts and times of one [`ShadowCasters::shadows`] call.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ShadowCounts {
    /// Casters considered (with at least one lit triangle).
    pub casters: u64,
    /// Casters culled (`z_max < z_min`, or every visible point nearer than the caster).
    pub casters_culled: u64,
    /// Casters whose volume was clamped at the back or front plane.
    pub casters_clamped: u64,
    /// Of those, front caps moved onto the `z_min` plane.
    pub front_caps_moved: u64,
    /// Lit triangles of the drawn casters.
    pub lit_triangles: u64,
    /// Extruded edges (silhouette and boundary edges, after cancellation).
    pub silhouette_edges: u64,
    /// N-buffer lookups.
    pub lookups: u64,
    /// Observer pixels reprojected into the litmaps.
    pub litmap_points: u64,
    /// The stencil pass.
    pub stencil: StencilCounts,
    /// Pixels shadowed.
    pub shadowed_pixels: u64,
    /// Milliseconds: litmaps (reprojection).
    pub litmap_ms: f64,
    /// Milliseconds: the two N-buffer builds.
    pub nbuffer_ms: f64,
    /// Milliseconds: lookups and volume construction.
    pub volumes_ms: f64,
    /// Milliseconds: the stencil pass.
    pub stencil_ms: f64,
}

/// The result: a state per pixel and the counts.
#[derive(Clone, Debug)]
pub struct ShadowFrame {
    /// One [`Shade`] per pixel, row-major.
    pub shades: Vec<Shade>,
    /// Counts and times.
    pub counts: ShadowCounts,
}

impl ShadowFrame {
    /// Darkens an RGBA8 image of the frame (`rgba`: 4 bytes per pixel, row-major, e.g. from
    /// `Frame::color_image` after `occult_raster::shade`): shadowed pixels to 40 %, pixels
    /// outside the light's frustum to 65 %.
    ///
    /// # Panics
    /// If `rgba` does not hold 4 bytes per shade (a programmer error).
    pub fn darken(&self, rgba: &mut [u8]) {
        assert_eq!(rgba.len(), self.shades.len() * 4, "image size differs");
        for (px, s) in rgba.chunks_exact_mut(4).zip(&self.shades) {
            let f = match s {
                Shade::Shadowed => 0.4,
                Shade::OutsideLight => 0.65,
                _ => 1.0,
            };
            for c in &mut px[..3] {
                *c = (*c as f32 * f) as u8;
            }
        }
    }
}

/// Light-space geometry of one frame.
struct LightSpace {
    position: DVec3,
    /// Unit axis.
    dir: DVec3,
    near: f64,
    clip_from_world: DMat4,
    resolution: u32,
}

impl LightSpace {
    fn new(light: &SpotLight, view: &View) -> Self {
        Self {
            position: light.position.as_dvec3(),
            dir: (light.target.as_dvec3() - light.position.as_dvec3()).normalize(),
            near: view.camera().near as f64,
            clip_from_world: view.clip_from_world().as_dmat4(),
            resolution: light.resolution,
        }
    }
    /// Distance along the light's axis.
    #[inline]
    fn depth(&self, p: DVec3) -> f64 {
        self.dir.dot(p - self.position)
    }
    /// The lexel of `p`, when it lies in the light's frustum beyond its near plane.
    #[inline]
    fn lexel(&self, p: DVec3) -> Option<(u32, u32)> {
        if !(self.depth(p) >= self.near) {
            return None;
        }
        let c = self.clip_from_world * p.extend(1.0);
        if !(c.w > 0.0 && c.x.abs() <= c.w && c.y.abs() <= c.w) {
            return None;
        }
        let r = self.resolution as f64;
        let x = ((c.x / c.w * 0.5 + 0.5) * r).floor().clamp(0.0, r - 1.0) as u32;
        let y = ((0.5 - c.y / c.w * 0.5) * r).floor().clamp(0.0, r - 1.0) as u32;
        Some((x, y))
    }
    /// Lexel rectangle (exclusive ends) holding the projections of `bounds`, widened by one
    /// lexel; the whole map when a corner lies behind the near plane.
    fn rect(&self, bounds: &Aabb) -> PixelRect {
        let r = self.resolution;
        let whole = PixelRect {
            x0: 0,
            y0: 0,
            x1: r,
            y1: r,
        };
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for corner in bounds.corners() {
            let p = corner.as_dvec3();
            if !(self.depth(p) >= self.near) {
                return whole;
            }
            let c = self.clip_from_world * p.extend(1.0);
            if !(c.w > 0.0) {
                return whole;
            }
            let q = DVec3::new(
                (c.x / c.w * 0.5 + 0.5) * r as f64,
                (0.5 - c.y / c.w * 0.5) * r as f64,
                0.0,
            );
            lo = lo.min(q);
            hi = hi.max(q);
        }
        let clampi = |v: f64| v.clamp(0.0, r as f64) as u32;
        PixelRect {
            x0: clampi(lo.x.floor() - 1.0),
            y0: clampi(lo.y.floor() - 1.0),
            x1: clampi(hi.x.floor() + 2.0),
            y1: clampi(hi.y.floor() + 2.0),
        }
    }
}

/// World positions of the observer's pixel centres at their depth.
fn unproject(world_from_clip: &DMat4, width: u32, height: u32, x: u32, y: u32, depth: f32) -> DVec3 {
    let ndc_x = (x as f64 + 0.5) / width as f64 * 2.0 - 1.0;
    let ndc_y = 1.0 - (y as f64 + 0.5) / height as f64 * 2.0;
    let h = *world_from_clip * DVec4::new(ndc_x, ndc_y, depth as f64, 1.0);
    h.truncate() / h.w
}

/// A mesh's BVH leaves: world-independent box and range of its leaf-ordered triangles.
type Leaves = Vec<(Aabb, std::ops::Range<u32>)>;
/// An undirected edge by its corners' position bits (smaller first).
type EdgeKey = ([u32; 3], [u32; 3]);

/// Positive `v` as `f32`, rounded up (`up`) or down (to the neighbouring float).
fn to_f32(v: f64, up: bool) -> f32 {
    let f = v as f32;
    if up && (f as f64) < v && f.is_finite() {
        f32::from_bits(f.to_bits() + 1)
    } else if !up && (f as f64) > v && f > 0.0 {
        f32::from_bits(f.to_bits() - 1)
    } else {
        f
    }
}

/// One caster's volume for the stencil pass.
#[derive(Default)]
struct Volume {
    instance: u32,
    /// Lit triangles drawn as interpolated front caps.
    caps: Vec<u32>,
    /// Generated faces (object space of the instance) and their world planes.
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    planes: Vec<[f64; 4]>,
    lit: u64,
    edges: u64,
    culled: bool,
    clamped: bool,
    front_moved: bool,
    lookups: u64,
}

/// The shadow volumes of one frame ([`ShadowCasters::volumes`]), ready for the stencil pass.
pub struct ShadowVolumes<'a> {
    casters: &'a ShadowCasters,
    /// Per observer pixel: its lexel and light depth, `None` outside the light.
    lexels: Vec<Option<(u32, f64)>>,
    volumes: Vec<Volume>,
    /// Front caps, grouped by mesh instance (one interpolated draw each), in instance order.
    cap_lists: Vec<(u32, Vec<u32>)>,
    /// Generated faces per caster: instance, mesh, first item.
    meshes: Vec<(u32, Mesh, ItemId)>,
    /// Everything counted up to the volumes.
    pub counts: ShadowCounts,
}

impl ShadowVolumes<'_> {
    /// The stencil pass (§3.3, §4.4): every volume's faces counted into a new stencil buffer
    /// under the z-fail rule against `frame`'s depth. `view` and `frame` must be those the
    /// volumes were built for.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] when a caster instance is not a mesh; raster errors
    /// (sizes, allocation).
    pub fn stencil(
        &self,
        raster: &mut Rasterizer,
        view: &View,
        frame: &Frame,
    ) -> Result<(StencilBuffer, StencilCounts)> {
        let plane_lists: Vec<&[[f64; 4]]> = self
            .volumes
            .iter()
            .filter(|v| v.lit > 0 && !v.culled && !v.triangles.is_empty())
            .map(|v| &v.planes[..])
            .collect();
        let casters = self.casters;
        let mut draws = Vec::with_capacity(self.cap_lists.len() + self.meshes.len());
        for (k, tris) in &self.cap_lists {
            let inst = &casters.instances[*k as usize];
            let mesh = casters
                .scene
                .node(inst.mesh)
                .mesh()
                .ok_or_else(|| RenderError::BadParameter("shadows: a caster instance is not a mesh".into()))?;
            draws.push(StencilDraw {
                draw: Draw {
                    mesh,
                    triangles: DrawTriangles::List(tris),
                    clip_from_object: view.clip_from_object(&inst.world_from_object),
                    first_item: inst.first_item,
                },
                faces: StencilFaces::Interpolated,
            });
        }
        for ((instance, mesh, first), planes) in self.meshes.iter().zip(plane_lists) {
            let inst = &casters.instances[*instance as usize];
            draws.push(StencilDraw {
                draw: Draw {
                    mesh,
                    triangles: DrawTriangles::All,
                    clip_from_object: view.clip_from_object(&inst.world_from_object),
                    first_item: *first,
                },
                faces: StencilFaces::Planes(planes),
            });
        }
        let mut stencil = StencilBuffer::new(frame.width(), frame.height())?;
        let counts = raster.draw_stencil(view, frame, &mut stencil, &draws)?;
        Ok((stencil, counts))
    }
}

impl ShadowCasters {
    /// The casters of `scene`: its mesh instances, meshes above `leaf` triangles split into
    /// the leaves of a BVH over their triangles.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for `leaf = 0` or a scene of more than
    /// [`MAX_SHADOW_TRIANGLES`] triangle instances (checked before anything is allocated).
    pub fn new(scene: std::sync::Arc<Scene>, leaf: usize) -> Result<Self> {
        if leaf == 0 {
            return Err(RenderError::BadParameter("shadows: leaf must be at least 1".into()));
        }
        if scene.item_count() > MAX_SHADOW_TRIANGLES {
            return Err(RenderError::BadParameter(format!(
                "shadows: the scene has {} triangle instances, more than {MAX_SHADOW_TRIANGLES}",
                scene.item_count()
            )));
        }
        let mut leaf_triangles = Vec::new();
        // Per node: (index into leaf_triangles, leaves as (node box, range)).
        let mut split: Vec<Option<(u32, Leaves)>> = vec![None; scene.nodes().len()];
        for (i, node) in scene.nodes().iter().enumerate() {
            if let Some(m) = node.mesh() {
                if m.triangle_count() > leaf {
                    let boxes = crate::nodes::triangle_boxes(m);
                    let bvh = Bvh::build(&boxes, leaf);
                    let order = bvh.primitive_indices().to_vec();
                    let leaves = bvh
                        .nodes()
                        .iter()
                        .filter(|n| n.is_leaf() && n.count > 0)
                        .map(|n| {
                            let r = n.range();
                            let b = order[r.clone()]
                                .iter()
                                .fold(Aabb::default(), |b, &t| b.union(boxes[t as usize]));
                            (b, r.start as u32..r.end as u32)
                        })
                        .collect();
                    split[i] = Some((leaf_triangles.len() as u32, leaves));
                    leaf_triangles.push(order);
                }
            }
        }
        let mut instances = Vec::new();
        let mut casters = Vec::new();
        scene.for_each_mesh_instance(|world_from_object, id, mesh, first_item| {
            let instance = instances.len() as u32;
            instances.push(InstanceRef {
                mesh: id,
                world_from_object: *world_from_object,
                first_item,
            });
            match &split[id.index()] {
                Some((k, leaves)) => {
                    for (b, r) in leaves {
                        casters.push(Caster {
                            instance,
                            leaf: Some((*k, r.clone())),
                            bounds: b.transformed(world_from_object),
                        });
                    }
                }
                None => casters.push(Caster {
                    instance,
                    leaf: None,
                    bounds: mesh.bounds().transformed(world_from_object),
                }),
            }
        });
        Ok(Self {
            scene,
            instances,
            casters,
            leaf_triangles,
        })
    }

    /// Number of casters.
    pub fn caster_count(&self) -> usize {
        self.casters.len()
    }

    /// Shadows of `light` on `frame` (already drawn by a conservative renderer from `view`):
    /// [`ShadowCasters::volumes`], then [`ShadowVolumes::stencil`], then each pixel's shade.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for a bad light (see [`SpotLight::view`]) or a frame whose
    /// size differs from the view's; raster errors (allocation).
    pub fn shadows(
        &self,
        raster: &mut Rasterizer,
        view: &View,
        frame: &Frame,
        light: &SpotLight,
        clamping: Clamping,
    ) -> Result<ShadowFrame> {
        let volumes = self.volumes(raster, view, frame, light, clamping)?;
        let t3 = Instant::now();
        let (stencil, stencil_counts) = volumes.stencil(raster, view, frame)?;
        let ShadowVolumes { lexels, mut counts, .. } = volumes;
        counts.stencil = stencil_counts;
        counts.stencil_ms = t3.elapsed().as_secs_f64() * 1e3;

        let shades: Vec<Shade> = lexels
            .iter()
            .zip(frame.depth())
            .zip(stencil.values())
            .map(|((l, &d), &s)| {
                if d == CLEAR_DEPTH || !d.is_finite() {
                    Shade::Sky
                } else if l.is_none() {
                    Shade::OutsideLight
                } else if s != 0 {
                    Shade::Shadowed
                } else {
                    Shade::Lit
                }
            })
            .collect();
        counts.shadowed_pixels = shades.iter().filter(|&&s| s == Shade::Shadowed).count() as u64;
        Ok(ShadowFrame { shades, counts })
    }

    /// The litmaps, culling, clamping and shadow volumes of `light` for `frame` (already drawn
    /// from `view`), ready for the stencil pass; `counts` holds everything but the stencil's.
    ///
    /// # Errors
    /// As [`ShadowCasters::shadows`].
    pub fn volumes(
        &self,
        raster: &mut Rasterizer,
        view: &View,
        frame: &Frame,
        light: &SpotLight,
        clamping: Clamping,
    ) -> Result<ShadowVolumes<'_>> {
        let light_view = light.view()?;
        let view_size = (view.width(), view.height());
        crate::check_same_size("shadows", "frame", (frame.width(), frame.height()), "view", view_size)?;
        let ls = LightSpace::new(light, &light_view);
        let mut counts = ShadowCounts::default();
        let (w, h) = (frame.width(), frame.height());
        let world_from_clip = view.clip_from_world().as_dmat4().inverse();

        // §3.3 "Generation of litmaps": the visible surface reprojected into the light's view.
        let t0 = Instant::now();
        let lexels: Vec<Option<(u32, f64)>> = raster.install(|| {
            frame
                .depth()
                .par_iter()
                .enumerate()
                .map(|(i, &d)| {
                    if d == CLEAR_DEPTH || !d.is_finite() {
                        return None;
                    }
                    let p = unproject(&world_from_clip, w, h, i as u32 % w, i as u32 / w, d);
                    ls.lexel(p).map(|(x, y)| (y * ls.resolution + x, ls.near / ls.depth(p)))
                })
                .collect()
        });
        let mut near_map = Vec::new();
        let mut far_map = Vec::new();
        let nbuffers;
        // Both modes build the N-buffers: the unclamped volumes are split where the clamped ones
        // end, so that near every visible point both are drawn with the same triangles.
        {
            let n = (ls.resolution * ls.resolution) as usize;
            // Reversed-Z light depth (near / distance): empty lexels read 0 (no point, never the
            // nearest) in the nearest map and +inf in the farthest map.
            near_map.resize(n, 0.0f32);
            far_map.resize(n, f32::INFINITY);
            for &(k, z) in lexels.iter().flatten() {
                counts.litmap_points += 1;
                let k = k as usize;
                near_map[k] = near_map[k].max(to_f32(z, true));
                far_map[k] = far_map[k].min(to_f32(z, false));
            }
            counts.litmap_ms = t0.elapsed().as_secs_f64() * 1e3;
            // §3.3 "Finding extents": N-buffers over both litmaps.
            let t1 = Instant::now();
            let r = ls.resolution;
            let (nearest, farthest) = raster.install(|| {
                rayon::join(
                    || NBuffer::new(Extremum::Max, &near_map, r, r),
                    || NBuffer::new(Extremum::Min, &far_map, r, r),
                )
            });
            nbuffers = Some((nearest?, farthest?));
            counts.nbuffer_ms = t1.elapsed().as_secs_f64() * 1e3;
        }

        // Beyond every point of the scene: where unclamped volumes end.
        let far_plane = self
            .scene
            .bounds()
            .corners()
            .iter()
            .map(|c| ls.depth(c.as_dvec3()))
            .fold(ls.near, f64::max)
            * 1.5
            + 1.0;

        let t2 = Instant::now();
        let volumes: Vec<Volume> = raster.install(|| {
            self.casters
                .par_iter()
                .map(|c| self.volume(c, &ls, far_plane, nbuffers.as_ref(), clamping))
                .collect()
        });
        // Front caps, grouped by mesh instance (one interpolated draw each).
        let mut cap_lists: HashMap<u32, Vec<u32>> = HashMap::new();
        let mut base: ItemId = self.scene.item_count();
        let mut meshes: Vec<(u32, Mesh, ItemId)> = Vec::new();
        for v in &volumes {
            if v.lit == 0 {
                continue;
            }
            counts.casters += 1;
            counts.casters_culled += v.culled as u64;
            counts.casters_clamped += v.clamped as u64;
            counts.front_caps_moved += v.front_moved as u64;
            counts.lookups += v.lookups;
            if v.culled {
                continue;
            }
            counts.lit_triangles += v.lit;
            counts.silhouette_edges += v.edges;
            if !v.caps.is_empty() {
                cap_lists.entry(v.instance).or_default().extend_from_slice(&v.caps);
            }
            if !v.triangles.is_empty() {
                let mesh = Mesh::new(v.positions.clone(), v.triangles.clone())
                    .map_err(|e| RenderError::BadParameter(format!("shadows: volume mesh: {e}")))?;
                meshes.push((v.instance, mesh, base));
                base += v.triangles.len() as u64;
            }
        }
        let mut cap_lists: Vec<(u32, Vec<u32>)> = cap_lists.into_iter().collect();
        cap_lists.sort_unstable_by_key(|&(k, _)| k);
        counts.volumes_ms = t2.elapsed().as_secs_f64() * 1e3;
        Ok(ShadowVolumes {
            casters: self,
            lexels,
            volumes,
            cap_lists,
            meshes,
            counts,
        })
    }

    /// The volume of one caster (§3.3 "Shadowing").
    fn volume(
        &self,
        caster: &Caster,
        ls: &LightSpace,
        far_plane: f64,
        nbuffers: Option<&(NBuffer, NBuffer)>,
        clamping: Clamping,
    ) -> Volume {
        let inst = &self.instances[caster.instance as usize];
        let mut v = Volume {
            instance: caster.instance,
            ..Volume::default()
        };
        let Some(mesh) = self.scene.node(inst.mesh).mesh() else {
            return v;
        };
        let world_from_object = Mat4::from(inst.world_from_object).as_dmat4();
        let light_obj = world_from_object.inverse().transform_point3(ls.position);
        let all: Vec<u32>;
        let tris: &[u32] = match &caster.leaf {
            Some((k, r)) => &self.leaf_triangles[*k as usize][r.start as usize..r.end as usize],
            None => {
                all = (0..mesh.triangle_count() as u32).collect();
                &all
            }
        };
        let pos = mesh.positions();
        let world = |i: u32| world_from_object.transform_point3(pos[i as usize].as_dvec3());
        // Lit triangles: front face toward the light, every corner beyond the light's near plane.
        let mut lit: Vec<(u32, [u32; 3])> = Vec::new();
        let (mut c_lo, mut c_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &t in tris {
            let idx = mesh.triangles()[t as usize];
            let [a, b, c] = idx.map(world);
            let n = (b - a).cross(c - a);
            if !(n.dot(ls.position - a) > 0.0) {
                continue;
            }
            let d = [a, b, c].map(|p| ls.depth(p));
            if !d.iter().all(|&d| d >= ls.near) {
                continue;
            }
            c_lo = c_lo.min(d[0].min(d[1]).min(d[2]));
            c_hi = c_hi.max(d[0].max(d[1]).max(d[2]));
            lit.push((t, idx));
        }
        v.lit = lit.len() as u64;
        if lit.is_empty() {
            return v;
        }
        // §3.3: extents from the N-buffers, culling and the clamping planes.
        let (mut front, mut back) = (None, far_plane);
        if let Some((nearest, farthest)) = nbuffers {
            let rect = ls.rect(&caster.bounds);
            let qn = nearest.query_four(rect);
            let qf = farthest.query_four(rect);
            v.lookups = (qn.lookups + qf.lookups) as u64;
            // Distances: z = near / distance (0 → infinitely far, +inf → at the light).
            let z_min = if qn.depth > 0.0 {
                ls.near / qn.depth as f64
            } else {
                f64::INFINITY
            };
            let z_max = if qf.depth.is_finite() {
                ls.near / qf.depth as f64
            } else {
                0.0
            };
            if z_max < z_min || z_max < c_lo * (1.0 - CLAMP_MARGIN) {
                if clamping == Clamping::On {
                    v.culled = true;
                    return v;
                }
            } else {
                let b = (z_max.max(c_hi) * (1.0 + CLAMP_MARGIN)).min(far_plane);
                if b < far_plane {
                    back = b;
                    v.clamped = true;
                }
                let f = z_min * (1.0 - CLAMP_MARGIN);
                if f > c_hi * (1.0 + CLAMP_MARGIN) {
                    front = Some(f);
                    v.clamped = true;
                    v.front_moved = true;
                }
            }
        }
        // Where the side faces are split: the clamping planes. Unclamped, the volume keeps its
        // caps (the lit triangles, the far plane) and only its sides are cut there, so that
        // the faces near any visible point (all lie between the planes) are the very triangles,
        // with the same snapped corners, that the clamped volume draws: a point on a shadow's
        // boundary is then classified alike in both modes.
        let splits: Vec<f64> = match clamping {
            Clamping::On => vec![back],
            Clamping::Off => front
                .into_iter()
                .chain((back < far_plane).then_some(back))
                .chain([far_plane])
                .collect(),
        };
        if clamping == Clamping::Off {
            v.clamped = false;
            v.front_moved = false;
            front = None;
            back = far_plane;
        }
        // A point of the object-space ray from the light through `p` at light distance `dist`.
        let at = |i: u32, dist: f64| -> Vec3 {
            let p = pos[i as usize].as_dvec3();
            let s = dist / ls.depth(world(i));
            (light_obj + (p - light_obj) * s).as_vec3()
        };
        let vertex = |v: &mut Volume, p: Vec3| {
            v.positions.push(p);
            v.positions.len() as u32 - 1
        };
        let front_plane = front.map(|f| {
            let n = -ls.dir;
            [n.x, n.y, n.z, ls.dir.dot(ls.position) + f]
        });
        let back_plane = [ls.dir.x, ls.dir.y, ls.dir.z, -ls.dir.dot(ls.position) - back];
        // Caps, wound counter-clockwise seen from outside the volume: the front cap as the lit
        // triangle (it faces the light), the back cap reversed.
        for &(t, [i0, i1, i2]) in &lit {
            match front_plane {
                None => v.caps.push(t),
                Some(fp) => {
                    let k = [i0, i1, i2].map(|i| vertex(&mut v, at(i, front.unwrap_or(0.0))));
                    v.triangles.push(k);
                    v.planes.push(fp);
                }
            }
            let [k0, k1, k2] = [i0, i1, i2].map(|i| vertex(&mut v, at(i, back)));
            v.triangles.push([k0, k2, k1]);
            v.planes.push(back_plane);
        }
        // Sides: directed edges of the lit triangles, shared ones cancelled (matched by position).
        let key = |i: u32| {
            let p = pos[i as usize];
            [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
        };
        let mut edges: HashMap<EdgeKey, (i32, u32, u32)> = HashMap::with_capacity(lit.len() * 3);
        for &(_, [i0, i1, i2]) in &lit {
            for (a, b) in [(i0, i1), (i1, i2), (i2, i0)] {
                let (ka, kb) = (key(a), key(b));
                if ka < kb {
                    edges.entry((ka, kb)).or_insert((0, a, b)).0 += 1;
                } else {
                    let e = edges.entry((kb, ka)).or_insert((0, b, a));
                    e.0 -= 1;
                }
            }
        }
        let mut sides: Vec<(i32, u32, u32)> = edges.into_values().filter(|e| e.0 != 0).collect();
        // A fixed order: the faces' order never changes counts, but keeps runs reproducible.
        sides.sort_unstable_by_key(|e| (e.1, e.2));
        for (m, lo, hi) in sides {
            let (a, b) = if m > 0 { (lo, hi) } else { (hi, lo) };
            let (aw, bw) = (world(a), world(b));
            // The plane through the light and the edge (its orientation does not matter: the
            // stencil pass counts by the winding on screen).
            let n = (aw - ls.position).cross(bw - ls.position);
            let plane = [n.x, n.y, n.z, -n.dot(ls.position)];
            for _ in 0..m.unsigned_abs() {
                v.edges += 1;
                let (mut an, mut bn) = match front {
                    None => (pos[a as usize], pos[b as usize]),
                    Some(f) => (at(a, f), at(b, f)),
                };
                // Unclamped, the first split is the moved front plane's place, not a start.
                let ends = splits.iter().filter(|&&d| front.is_none_or(|f| d > f));
                for &d in ends {
                    let (a2, b2) = (at(a, d), at(b, d));
                    let ia = vertex(&mut v, an);
                    let ib = vertex(&mut v, bn);
                    let fa = vertex(&mut v, a2);
                    let fb = vertex(&mut v, b2);
                    // The quad b, a, a', b': counter-clockwise seen from outside for the edge
                    // a → b of a triangle that faces the light.
                    v.triangles.push([ib, ia, fa]);
                    v.triangles.push([ib, fa, fb]);
                    v.planes.push(plane);
                    v.planes.push(plane);
                    (an, bn) = (a2, b2);
                }
            }
        }
        v
    }
}
