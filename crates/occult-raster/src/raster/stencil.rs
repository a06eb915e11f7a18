//! The stencil pass: shadow-volume faces counted per pixel by the one rasterizer.
//!
//! # References
//! Décoret, *N-Buffers for efficient depth map query*, 2005 (`papers/n-buffers-decoret-2005.txt`),
//! §3.3 and §4.4: shadow volumes are drawn into a stencil buffer and their fill rate (the
//! stencil fragments) is what clamping saves. The counting rule is the depth-fail rule
//! ("Carmack's reverse"): a face fragment that is *not nearer* than the frame's depth at its
//! pixel adds +1 when the face is a back face seen from the eye and −1 when it is a front face.
//! Faces must be wound counter-clockwise seen from outside their volume; front and back are
//! decided by the snapped triangle's orientation on screen, as a GPU does, so that the signed
//! coverage of a closed volume cancels exactly at every pixel centre (a sliver whose snapped
//! corners twist it still counts consistently).
//! For closed volumes (front and back caps drawn) a pixel's count is then the number of volumes
//! that contain its visible point, whatever the eye's position (near-plane clipping only removes
//! fragments nearer than every visible point, which never count).
//!
//! # How it uses the rasterizer
//! Faces go through the rasterizer's own setup (projection, homogeneous clipping, snapping,
//! fill rule) and their covered pixel centres are found from the same exact integer edge
//! functions as [`super::scan_triangle`] (tested: same pixels as a `Full` draw). The frame's
//! depth is read, never written. Back-face culling and the far plane are off for this pass: a
//! volume's far cap may lie beyond the camera's far plane and must still count.
//!
//! # Face depth
//! Two rules, chosen per draw ([`StencilFaces`]):
//! - **Interpolated**: the rasterizer's own depth plane of the snapped triangle, as in a
//!   `Full` draw. A cap that is the caster's own triangle, drawn through the same mesh and
//!   matrix as in the frame, then has bit-identical depth where it is the visible surface; the
//!   tie counts (not nearer), so a lit face is not shadowed by its own cap.
//! - **Plane** (deviation from a GPU's interpolation): the depth of the face's exact world
//!   plane at the pixel centre, evaluated in `f64` from the plane alone. Two faces on the same
//!   plane (a shadow-volume side and its clamped part) then give the same answer at every
//!   pixel, so clamping cannot move a shadow boundary by rounding.
//!
//! Cost: O(faces × bands + covered pixels); rows are split into one band per thread and each
//! band sets up every face (setup is cheap next to the fill of shadow volumes).

use super::{draw_starts, setup_range, Draw, DrawTriangles, Rasterizer, SetupSink, TriSetup, TriStream, Viewport};
use crate::{Frame, RasterError, CLEAR_DEPTH};
use occult_core::{glam::DMat4, glam::DVec4, ItemId, View};

/// A `width × height` buffer of signed stencil counts, row-major, kept beside a [`Frame`]
/// (allocated only by the passes that need it).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StencilBuffer {
    width: u32,
    height: u32,
    values: Vec<i32>,
}

impl StencilBuffer {
    /// A zeroed buffer.
    ///
    /// # Errors
    /// [`RasterError::Resolution`] for a zero or oversized resolution; [`RasterError::OutOfMemory`]
    /// when it cannot be allocated (checked before allocating).
    pub fn new(width: u32, height: u32) -> Result<Self, RasterError> {
        occult_core::check_resolution(width, height)?;
        let n = width as usize * height as usize;
        let mut values = Vec::new();
        values
            .try_reserve_exact(n)
            .map_err(|_| RasterError::OutOfMemory(n * 4))?;
        values.resize(n, 0);
        Ok(Self { width, height, values })
    }
    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }
    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }
    /// Counts per pixel, row-major.
    pub fn values(&self) -> &[i32] {
        &self.values
    }
    /// Resets every count to 0.
    pub fn clear(&mut self) {
        self.values.fill(0);
    }
    /// Pixels whose count is not 0.
    pub fn nonzero_count(&self) -> u64 {
        self.values.iter().filter(|&&v| v != 0).count() as u64
    }
}

/// How the depth of a [`StencilDraw`]'s triangles is found.
#[derive(Clone, Copy, Debug)]
pub enum StencilFaces<'a> {
    /// The rasterizer's interpolated depth (see the module doc).
    Interpolated,
    /// Exact plane depth: one world-space plane `(n, d)` (`n·p + d = 0`) per triangle, indexed
    /// by the mesh's triangle index (`item − first_item`); the slice must cover every triangle.
    Planes(&'a [[f64; 4]]),
}

/// A draw of shadow-volume faces.
#[derive(Clone, Debug)]
pub struct StencilDraw<'a> {
    /// The triangles; item ranges `first_item + triangle index` of the draws must not overlap.
    pub draw: Draw<'a>,
    /// How each triangle's depth and increment are found.
    pub faces: StencilFaces<'a>,
}

/// Counts of one [`Rasterizer::draw_stencil`] call.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StencilCounts {
    /// Triangles handed in.
    pub triangles_submitted: u64,
    /// Triangles set up with a pixel box on screen (one cut into pieces by clipping counts
    /// once).
    pub triangles_rasterized: u64,
    /// Covered pixel centres of all faces: the fill rate of the pass (§4.4).
    pub fragments: u64,
    /// Fragments not nearer than the visible surface, which changed a count.
    pub updates: u64,
}

add_assign_fields!(StencilCounts {
    triangles_submitted,
    triangles_rasterized,
    fragments,
    updates,
});

/// A face's depth as an affine function of the pixel centre, `z = a·x + b·y + c`
/// (`x`, `y` in pixels, centres at `+ 0.5`); not `exact` for a plane through the eye (seen
/// edge-on), whose fragments then take the interpolated depth.
#[derive(Clone, Copy, Debug)]
struct ScreenPlane {
    a: f64,
    b: f64,
    c: f64,
    exact: bool,
}

/// Maps world planes to screen-space depth planes of one view.
struct PlaneMapper {
    /// `(clip_from_world⁻¹)ᵀ`: world planes to clip-space planes.
    clip_plane_from_world_plane: DMat4,
    width: f64,
    height: f64,
}

impl PlaneMapper {
    fn new(view: &View) -> Self {
        let m = view.clip_from_world().as_dmat4();
        Self {
            clip_plane_from_world_plane: m.inverse().transpose(),
            width: view.width() as f64,
            height: view.height() as f64,
        }
    }

    /// The screen depth plane of world plane `p`: a clip-space plane `q` holds the points with
    /// `q.x·x_ndc + q.y·y_ndc + q.z·z_ndc + q.w = 0`, and `x_ndc = 2x/W − 1`, `y_ndc = 1 − 2y/H`.
    fn map(&self, p: [f64; 4]) -> ScreenPlane {
        let q = self.clip_plane_from_world_plane * DVec4::from_array(p);
        if q.z == 0.0 || !q.is_finite() {
            return ScreenPlane {
                a: 0.0,
                b: 0.0,
                c: 0.0,
                exact: false,
            };
        }
        let inv = -1.0 / q.z;
        ScreenPlane {
            a: q.x * 2.0 / self.width * inv,
            b: -q.y * 2.0 / self.height * inv,
            c: (q.y - q.x + q.w) * inv,
            exact: true,
        }
    }
}

/// One draw's faces, found by item.
struct FaceTable<'a> {
    first_item: ItemId,
    end_item: ItemId,
    /// Empty for interpolated depth.
    planes: Vec<ScreenPlane>,
    _faces: std::marker::PhantomData<&'a ()>,
}

impl Rasterizer {
    /// Draws shadow-volume faces into `stencil` under the z-fail rule against `frame`'s depth
    /// (read only; see the module doc). `stencil` is not cleared first. Pixels with no visible
    /// surface (cleared depth) are never counted.
    ///
    /// # Errors
    /// [`RasterError::BadConfig`] when the frame, stencil and view sizes differ, when two
    /// draws' item ranges overlap, or when a draw's face slice is shorter than its mesh's
    /// triangle count; [`RasterError::OutOfMemory`] when the screen planes cannot be allocated.
    pub fn draw_stencil(
        &mut self,
        view: &View,
        frame: &Frame,
        stencil: &mut StencilBuffer,
        draws: &[StencilDraw<'_>],
    ) -> Result<StencilCounts, RasterError> {
        let size = (view.width(), view.height());
        if (frame.width(), frame.height()) != size || (stencil.width, stencil.height) != size {
            return Err(RasterError::BadConfig(format!(
                "stencil pass: view {}x{}, frame {}x{}, stencil {}x{} differ",
                size.0,
                size.1,
                frame.width(),
                frame.height(),
                stencil.width,
                stencil.height
            )));
        }
        let mapper = PlaneMapper::new(view);
        let mut tables = Vec::with_capacity(draws.len());
        for sd in draws {
            let n = sd.draw.mesh.triangle_count();
            let planes = match sd.faces {
                StencilFaces::Interpolated => Vec::new(),
                StencilFaces::Planes(p) => {
                    if p.len() < n {
                        return Err(RasterError::BadConfig(format!(
                            "stencil pass: {} planes for a mesh of {n} triangles",
                            p.len()
                        )));
                    }
                    let mut planes = Vec::new();
                    planes
                        .try_reserve_exact(p.len())
                        .map_err(|_| RasterError::OutOfMemory(p.len() * std::mem::size_of::<ScreenPlane>()))?;
                    planes.extend(p.iter().map(|&p| mapper.map(p)));
                    planes
                }
            };
            tables.push(FaceTable {
                first_item: sd.draw.first_item,
                end_item: sd.draw.first_item.saturating_add(n as u64),
                planes,
                _faces: std::marker::PhantomData,
            });
        }
        tables.sort_by_key(|t| t.first_item);
        if tables
            .windows(2)
            .any(|w| w[1].first_item < w[0].end_item && w[0].end_item > w[0].first_item)
        {
            return Err(RasterError::BadConfig(
                "stencil pass: draws' item ranges overlap".into(),
            ));
        }
        // Whole-mesh draws become ranges: the setup then projects each corner itself and no
        // pre-transformed vertex buffer is needed.
        let plain: Vec<Draw<'_>> = draws
            .iter()
            .map(|sd| {
                let mut d = sd.draw.clone();
                if matches!(d.triangles, DrawTriangles::All) {
                    d.triangles = DrawTriangles::Range(0..d.mesh.triangle_count() as u32);
                }
                d
            })
            .collect();
        let draw_starts = draw_starts(&plain);
        let total = draw_starts[plain.len()];
        let vertex_offsets = vec![0usize; plain.len()];
        let stream = TriStream::new(&plain, &draw_starts, &vertex_offsets, &[]);
        let mut vp = Viewport::new(view, &self.config);
        vp.cull_backfaces = false;
        vp.far_depth = f32::NEG_INFINITY;
        let width = size.0 as usize;
        let threads = self.thread_count().max(1);
        let band_rows = (size.1 as usize).div_ceil(threads).max(1);
        let depth = frame.depth();
        let bands = stencil.values.chunks_mut(band_rows * width).enumerate().collect();
        let mut counts = StencilCounts::default();
        for band in self.workers(threads).share(bands, |(band, values)| {
            let y0 = (band * band_rows) as u32;
            let y1 = y0 + (values.len() / width) as u32 - 1;
            let mut sink = StencilSink {
                rect: [0, y0, size.0 - 1, y1],
                tables: &tables,
                depth,
                values,
                width,
                counts: StencilCounts::default(),
            };
            if total > 0 {
                setup_range::<false>(&vp, &stream, 0..total, &mut sink);
            }
            sink.counts
        }) {
            counts += band;
        }
        Ok(StencilCounts {
            triangles_submitted: total as u64,
            ..counts
        })
    }
}

/// Counts the fragments of one band of rows.
struct StencilSink<'a> {
    rect: [u32; 4],
    tables: &'a [FaceTable<'a>],
    depth: &'a [f32],
    /// The band's rows of the stencil.
    values: &'a mut [i32],
    width: usize,
    counts: StencilCounts,
}

impl SetupSink for StencilSink<'_> {
    fn count_uncovered(&mut self, n: u32) {
        self.counts.triangles_rasterized += (self.rect[1] == 0) as u64 * n as u64;
    }

    fn uncount(&mut self, n: u32) {
        self.counts.triangles_rasterized -= (self.rect[1] == 0) as u64 * n as u64;
    }

    fn push(&mut self, _vp: &Viewport, t: TriSetup) {
        // Every band sets up every face: the first band counts them.
        self.counts.triangles_rasterized += (self.rect[1] == 0) as u64;
        let k = self.tables.partition_point(|tb| tb.first_item <= t.item) - 1;
        let table = &self.tables[k];
        let index = (t.item - table.first_item) as usize;
        let rect = self.rect;
        let (width, depth, values) = (self.width, self.depth, &mut *self.values);
        let (mut fragments, mut updates) = (0u64, 0u64);
        // Depth-fail: +1 for a back face, −1 for a front face, by orientation on screen.
        let increment = if t.front { -1 } else { 1 };
        let plane = table.planes.get(index).copied().filter(|p| p.exact);
        covered_spans(&t, rect, |y, xa, xb| {
            let base = y as usize * width;
            let sbase = (y - rect[1]) as usize * width;
            match plane {
                None => {
                    let row_depth = super::row_depth(&t, y);
                    for x in xa..=xb {
                        let stored = depth[base + x as usize];
                        let z = super::depth_at(&t, row_depth, x);
                        if stored != CLEAR_DEPTH && z <= stored {
                            values[sbase + x as usize] += increment;
                            updates += 1;
                        }
                    }
                }
                Some(p) => {
                    let row = p.b * (y as f64 + 0.5) + p.c;
                    for x in xa..=xb {
                        let stored = depth[base + x as usize];
                        let z = p.a * (x as f64 + 0.5) + row;
                        if stored != CLEAR_DEPTH && z <= stored as f64 {
                            values[sbase + x as usize] += increment;
                            updates += 1;
                        }
                    }
                }
            }
            fragments += (xb - xa + 1) as u64;
        });
        self.counts.fragments += fragments;
        self.counts.updates += updates;
    }
}

/// Calls `f(y, xa, xb)` for each row `y` of `rect` (inclusive) where triangle `t` covers the
/// pixel centres `xa..=xb`: the coverage of [`super::scan_triangle`] (same edge functions, same
/// top-left bias), found per row by solving each edge for its span.
fn covered_spans(t: &TriSetup, rect: [u32; 4], mut f: impl FnMut(u32, u32, u32)) {
    let Some([x0, y0, x1, y1]) = super::box_in(t, rect) else {
        return;
    };
    let (mut row, step_x, step_y) = super::edge_functions(t, x0, y0);
    let width = (x1 - x0 + 1) as i64;
    for y in y0..=y1 {
        let (lo, hi) = super::solve_span(row, step_x, 0, width - 1);
        if lo <= hi {
            f(y, x0 + lo as u32, x0 + hi as u32);
        }
        row[0] += step_y[0];
        row[1] += step_y[1];
        row[2] += step_y[2];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{RasterConfig, RasterMode};
    use occult_core::{glam::DVec3, Affine3A, Camera, Mat4, Mesh, Vec3};
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64Mcg;

    fn view(w: u32, h: u32) -> View {
        let mut c = Camera::look_at(Vec3::new(0.5, 1.0, 6.0), Vec3::ZERO);
        c.far = 1.0e6;
        View::new(c, w, h).expect("a valid test view")
    }

    fn world_plane(t: [Vec3; 3]) -> [f64; 4] {
        let [a, b, c] = t.map(|v| v.as_dvec3());
        let n = (b - a).cross(c - a);
        [n.x, n.y, n.z, -n.dot(a)]
    }

    /// Depth of world plane `p` at pixel centre `(x, y)` by intersecting the eye ray with it.
    fn ray_plane_depth(view: &View, p: [f64; 4], x: u32, y: u32) -> Option<f64> {
        let m = view.clip_from_world().as_dmat4();
        let inv = m.inverse();
        let ndc_x = (x as f64 + 0.5) / view.width() as f64 * 2.0 - 1.0;
        let ndc_y = 1.0 - (y as f64 + 0.5) / view.height() as f64 * 2.0;
        let at = |z: f64| {
            let h = inv * DVec4::new(ndc_x, ndc_y, z, 1.0);
            h.truncate() / h.w
        };
        let (o, q) = (at(1.0), at(0.5));
        let n = DVec3::new(p[0], p[1], p[2]);
        let denom = n.dot(q - o);
        if denom == 0.0 {
            return None;
        }
        let s = -(n.dot(o) + p[3]) / denom;
        let hit = o + (q - o) * s;
        let c = m * hit.extend(1.0);
        (c.w > 0.0).then_some(c.z / c.w)
    }

    /// The stencil pass against a brute force: each face drawn alone by `Full` draws gives its
    /// coverage and interpolated depth, front pieces (those a back-face-culling draw keeps)
    /// count −1 and back pieces +1; plane depths come from ray–plane intersections.
    #[test]
    fn stencil_pass_matches_brute_force() {
        let (w, h) = (48u32, 40u32);
        let v = view(w, h);
        for seed in 0..40u64 {
            let mut rng = Pcg64Mcg::seed_from_u64(seed);
            let mut rp = || {
                Vec3::new(
                    rng.random_range(-4.0..4.0),
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-6.0..9.0),
                )
            };
            // Receivers: a few triangles forming the frame's depth.
            let recv: Vec<Vec3> = (0..9).map(|_| rp()).collect();
            let recv = Mesh::new(recv, vec![[0, 1, 2], [3, 4, 5], [6, 7, 8]])
                .expect("three in-range triangles are a valid mesh");
            let mut raster = Rasterizer::new(RasterConfig {
                threads: 2,
                ..Default::default()
            })
            .expect("two threads are a valid raster config");
            let mut culling = Rasterizer::new(RasterConfig {
                cull_backfaces: true,
                ..Default::default()
            })
            .expect("backface culling is a valid raster config");
            let mut frame = Frame::new(w, h).expect("a frame of the view's size");
            let m = v.clip_from_object(&Affine3A::IDENTITY);
            let draw = |mesh, first_item| Draw {
                mesh,
                triangles: DrawTriangles::All,
                clip_from_object: m,
                first_item,
            };
            raster.draw(&v, &mut frame, &[draw(&recv, 0)], RasterMode::Full);
            // Faces: some re-use the receivers' triangles (exact ties), the rest random.
            let face_count = 8;
            let mut pos: Vec<Vec3> = Vec::new();
            for k in 0..face_count {
                if k < 2 {
                    pos.extend(recv.triangle_positions(k));
                } else {
                    for _ in 0..3 {
                        pos.push(rp());
                    }
                }
            }
            let tris: Vec<[u32; 3]> = (0..face_count as u32).map(|k| [3 * k, 3 * k + 1, 3 * k + 2]).collect();
            let faces_mesh = Mesh::new(pos, tris).expect("in-range face triangles are a valid mesh");
            let planes: Vec<[f64; 4]> = (0..face_count)
                .map(|k| world_plane(faces_mesh.triangle_positions(k)))
                .collect();
            let draws = [
                StencilDraw {
                    draw: draw(&recv, 0),
                    faces: StencilFaces::Interpolated,
                },
                StencilDraw {
                    draw: draw(&faces_mesh, 100),
                    faces: StencilFaces::Interpolated,
                },
                StencilDraw {
                    draw: draw(&faces_mesh, 200),
                    faces: StencilFaces::Planes(&planes),
                },
            ];
            let mut stencil = StencilBuffer::new(w, h).expect("a stencil of the view's size");
            let counts = raster
                .draw_stencil(&v, &frame, &mut stencil, &draws)
                .expect("a stencil of the frame's size and complete face lists");

            // Brute force.
            let mut expected = vec![0i32; (w * h) as usize];
            let mut ambiguous = vec![false; (w * h) as usize];
            let mut fragments = 0u64;
            let mut one = |mesh: &Mesh, k: usize, by_plane: Option<[f64; 4]>| {
                let (mut all, mut front) = (
                    Frame::new(w, h).expect("a frame of the view's size"),
                    Frame::new(w, h).expect("a frame of the view's size"),
                );
                let d = Draw {
                    mesh,
                    triangles: DrawTriangles::Range(k as u32..k as u32 + 1),
                    clip_from_object: m,
                    first_item: 0,
                };
                raster.draw(&v, &mut all, std::slice::from_ref(&d), RasterMode::Full);
                culling.draw(&v, &mut front, &[d], RasterMode::Full);
                for i in 0..(w * h) as usize {
                    if all.items()[i] == occult_core::NO_ITEM {
                        continue;
                    }
                    fragments += 1;
                    let stored = frame.depth()[i];
                    if stored == CLEAR_DEPTH {
                        continue;
                    }
                    let inc = if front.items()[i] == occult_core::NO_ITEM {
                        1
                    } else {
                        -1
                    };
                    let (x, y) = (i as u32 % w, i as u32 / w);
                    let z = match by_plane {
                        None => all.depth()[i] as f64,
                        Some(p) => match ray_plane_depth(&v, p, x, y) {
                            Some(z) => z,
                            None => {
                                ambiguous[i] = true;
                                continue;
                            }
                        },
                    };
                    if by_plane.is_some() && (z - stored as f64).abs() <= 1e-6 * stored as f64 {
                        ambiguous[i] = true;
                    }
                    if z <= stored as f64 {
                        expected[i] += inc;
                    }
                }
            };
            for k in 0..3 {
                one(&recv, k, None);
            }
            for k in 0..face_count {
                one(&faces_mesh, k, None);
            }
            for (k, &p) in planes.iter().enumerate() {
                one(&faces_mesh, k, Some(p));
            }
            assert_eq!(counts.fragments, fragments, "seed {seed}: fill");
            let mut compared = 0;
            for i in 0..(w * h) as usize {
                if !ambiguous[i] {
                    assert_eq!(stencil.values()[i], expected[i], "seed {seed}, pixel {i}");
                    compared += 1;
                }
            }
            // Faces that re-use receivers are ties, left out wherever their depths agree to
            // 10⁻⁶: on a view where receivers fill much of the frame that is a fifth of it.
            assert!(
                compared > (w * h) as usize * 3 / 4,
                "seed {seed}: {compared} pixels compared"
            );
            assert_eq!(counts.triangles_submitted, 3 + 2 * face_count as u64);
        }
    }

    #[test]
    fn a_visible_triangle_ties_with_its_own_cap() {
        let v = view(32, 32);
        let mesh = Mesh::new(
            vec![
                Vec3::new(-2.0, -2.0, 0.0),
                Vec3::new(2.0, -2.0, 0.0),
                Vec3::new(0.0, 2.0, 0.0),
            ],
            vec![[0, 1, 2]],
        )
        .expect("one in-range triangle is a valid mesh");
        let m = v.clip_from_object(&Affine3A::IDENTITY);
        let d = Draw {
            mesh: &mesh,
            triangles: DrawTriangles::All,
            clip_from_object: m,
            first_item: 5,
        };
        let mut raster = Rasterizer::new(RasterConfig::default()).expect("the default raster config is valid");
        let mut frame = Frame::new(32, 32).expect("a 32x32 frame");
        raster.draw(&v, &mut frame, std::slice::from_ref(&d), RasterMode::Full);
        let mut stencil = StencilBuffer::new(32, 32).expect("a 32x32 stencil");
        let sd = StencilDraw {
            draw: d,
            faces: StencilFaces::Interpolated,
        };
        let c = raster
            .draw_stencil(&v, &frame, &mut stencil, &[sd])
            .expect("a stencil of the frame's size and interpolated faces");
        assert_eq!(c.fragments, frame.covered_pixel_count());
        assert_eq!(c.updates, c.fragments);
        // Counter-clockwise toward the eye: a front face, −1 wherever it is the visible surface.
        assert!(stencil.values().iter().all(|&s| s == 0 || s == -1));
        assert_eq!(stencil.nonzero_count(), frame.covered_pixel_count());
    }

    #[test]
    fn bad_stencil_inputs_are_errors() {
        let v = view(16, 8);
        let frame = Frame::new(16, 8).expect("a 16x8 frame");
        let mut raster = Rasterizer::new(RasterConfig::default()).expect("the default raster config is valid");
        let mut wrong = StencilBuffer::new(8, 8).expect("an 8x8 stencil");
        assert!(raster.draw_stencil(&v, &frame, &mut wrong, &[]).is_err());
        assert!(StencilBuffer::new(0, 8).is_err());
        let mesh = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]])
            .expect("one in-range triangle is a valid mesh");
        let d = Draw {
            mesh: &mesh,
            triangles: DrawTriangles::All,
            clip_from_object: Mat4::IDENTITY,
            first_item: 0,
        };
        let mut s = StencilBuffer::new(16, 8).expect("a 16x8 stencil");
        let short = StencilDraw {
            draw: d.clone(),
            faces: StencilFaces::Planes(&[]),
        };
        assert!(raster.draw_stencil(&v, &frame, &mut s, &[short]).is_err());
        let a = StencilDraw {
            draw: d.clone(),
            faces: StencilFaces::Interpolated,
        };
        assert!(raster.draw_stencil(&v, &frame, &mut s, &[a.clone(), a]).is_err());
    }
}
