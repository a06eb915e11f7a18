//! The oracle (rasterizing exactly the visible triangles) and the measures of an image that
//! do not depend on the renderers: image complexity, and the error of a differing frame.

use std::time::Instant;

use occult_core::{ItemId, Mat4, Mesh, NodeId, NodeKind, Scene, Vec4, View, NO_ITEM};
use occult_raster::{Draw, DrawTriangles, Frame, RasterError, RasterMode, Rasterizer};
use occult_render::walk::{NodeAt, NodeTest, SceneWalk, Visitor};
use occult_render::RenderOptions;
use rayon::prelude::*;

use super::report::ms;

/// Rasterizes exactly a given set of items: the lower bound of any culling renderer.
pub(crate) struct Oracle {
    raster: Rasterizer,
}

/// The visible triangles of one mesh instance.
struct InstanceTriangles {
    mesh_node: NodeId,
    instance_base: ItemId,
    clip_from_object: Mat4,
    triangle_indices: Vec<u32>,
}

impl Oracle {
    /// An oracle rasterizing with `options`' rasterizer settings.
    pub(crate) fn new(options: &RenderOptions) -> Result<Self, RasterError> {
        Ok(Self {
            raster: Rasterizer::new(options.raster.clone())?,
        })
    }

    /// Clears `frame` and rasterizes the items `visible` (sorted, as
    /// [`Frame::visible_items`] returns them); returns the time of the clear and the draw, ms.
    /// Resolving items into draws is the oracle's knowledge and is not timed.
    pub(crate) fn render(&mut self, scene: &Scene, view: &View, visible: &[ItemId], frame: &mut Frame) -> f64 {
        // Items of one mesh instance are consecutive ids, so sorted items group by instance.
        let mut groups: Vec<InstanceTriangles> = Vec::new();
        for &item in visible {
            let Some(loc) = scene.resolve_item(item) else {
                continue; // Not an item of this scene (cannot happen for frames of this scene).
            };
            match groups.last_mut() {
                Some(g) if g.instance_base == loc.instance_base && g.mesh_node == loc.mesh_node => {
                    g.triangle_indices.push(loc.triangle_index)
                }
                _ => groups.push(InstanceTriangles {
                    mesh_node: loc.mesh_node,
                    instance_base: loc.instance_base,
                    clip_from_object: view.clip_from_object(&loc.world_from_object),
                    triangle_indices: vec![loc.triangle_index],
                }),
            }
        }
        let draws: Vec<Draw<'_>> = groups
            .iter()
            .filter_map(|g| {
                Some(Draw {
                    mesh: scene.node(g.mesh_node).mesh()?,
                    triangles: DrawTriangles::List(&g.triangle_indices),
                    clip_from_object: g.clip_from_object,
                    first_item: g.instance_base,
                })
            })
            .collect();
        let t = Instant::now();
        frame.clear();
        self.raster.draw(view, frame, &draws, RasterMode::Full);
        ms(t.elapsed())
    }
}

/// Image complexity |Ω| of one view (Han & Zeiger §I): the summed screen area, in pixels, of
/// every triangle instance clipped to the view frustum (near, far, four sides), back faces
/// included. Instances whose bounds lie outside the frustum are skipped whole; the cost is one
/// transform and clip per triangle instance in the view, over rayon's threads.
pub fn image_complexity(scene: &Scene, view: &View) -> f64 {
    let mut in_frustum = InFrustum {
        walk: SceneWalk::new(scene, view),
        meshes: Vec::new(),
    };
    in_frustum.run();
    let instances = in_frustum.meshes;
    let (w, h) = (view.width() as f64, view.height() as f64);
    let (near, far) = (view.camera().near, view.camera().far);
    instances
        .par_iter()
        .map(|(clip_from_object, mesh)| {
            let p = mesh.positions();
            mesh.triangles()
                .par_chunks(4096)
                .map(|chunk| {
                    chunk
                        .iter()
                        .map(|t| {
                            let c = t.map(|i| *clip_from_object * p[i as usize].extend(1.0));
                            clipped_screen_area(&c, near, far) * 0.25 * w * h
                        })
                        .sum::<f64>()
                })
                .sum::<f64>()
        })
        .sum()
}

/// The mesh instances whose bounds are not outside the view frustum, with their
/// `clip_from_object`: the scene walk every renderer uses, each node's box tested uncounted.
struct InFrustum<'s> {
    walk: SceneWalk<'s>,
    meshes: Vec<(Mat4, &'s Mesh)>,
}

impl<'s> Visitor<'s> for InFrustum<'s> {
    const NODE_TEST: NodeTest = NodeTest::Uncounted;

    fn walk(&mut self) -> &mut SceneWalk<'s> {
        &mut self.walk
    }

    fn visit(&mut self, at: &NodeAt<'s>) {
        match at.node.kind() {
            NodeKind::Mesh(m) => {
                let clip_from_object = self.walk.view().clip_from_object(&at.place.world_from_node);
                self.meshes.push((clip_from_object, m));
            }
            NodeKind::Group(instances) => {
                for i in 0..instances.len() {
                    self.enter(at.child(i), at.inside);
                }
            }
        }
    }
}

/// Area in normalized device coordinates (the screen is 2 × 2) of the clip-space triangle `c`
/// clipped to `near <= w <= far` and `|x|, |y| <= w` (Sutherland–Hodgman in homogeneous
/// coordinates).
fn clipped_screen_area(c: &[Vec4; 3], near: f32, far: f32) -> f64 {
    let planes: [fn(&Vec4, f32, f32) -> f32; 6] = [
        |v, n, _| v.w - n,
        |v, _, f| f - v.w,
        |v, _, _| v.w + v.x,
        |v, _, _| v.w - v.x,
        |v, _, _| v.w + v.y,
        |v, _, _| v.w - v.y,
    ];
    // Up to 3 + 6 vertices after six planes.
    let mut poly = [Vec4::ZERO; 9];
    poly[..3].copy_from_slice(c);
    let mut len = 3;
    let mut next = [Vec4::ZERO; 9];
    for plane in planes {
        let d: [f32; 9] = std::array::from_fn(|i| if i < len { plane(&poly[i], near, far) } else { 0.0 });
        if d[..len].iter().all(|&x| x >= 0.0) {
            continue;
        }
        let mut n = 0;
        for i in 0..len {
            let j = (i + 1) % len;
            if d[i] >= 0.0 {
                next[n] = poly[i];
                n += 1;
            }
            if (d[i] >= 0.0) != (d[j] >= 0.0) {
                next[n] = poly[i] + (poly[j] - poly[i]) * (d[i] / (d[i] - d[j]));
                n += 1;
            }
        }
        std::mem::swap(&mut poly, &mut next);
        len = n;
        if len < 3 {
            return 0.0;
        }
    }
    let ndc = |v: &Vec4| ((v.x / v.w) as f64, (v.y / v.w) as f64);
    let twice: f64 = (0..len)
        .map(|i| {
            let (a, b) = (ndc(&poly[i]), ndc(&poly[(i + 1) % len]));
            a.0 * b.1 - b.0 * a.1
        })
        .sum();
    twice.abs() * 0.5
}

/// Share of pixels covered in either frame whose item differs (0 when neither covers any).
pub(crate) fn item_error(frame: &Frame, reference: &Frame) -> f64 {
    let covered = frame
        .items()
        .iter()
        .zip(reference.items())
        .filter(|(&a, &b)| a != NO_ITEM || b != NO_ITEM)
        .count();
    if covered == 0 {
        return 0.0;
    }
    frame.differing_item_count(reference) as f64 / covered as f64
}

/// Subsamples per pixel and axis of the supersampled reference of [`paper_error`].
pub(crate) const SUPERSAMPLE: u32 = 4;
/// Most pixels of the supersampled reference (fewer subsamples per axis beyond).
pub(crate) const MAX_FINE_PIXELS: u64 = 1 << 24;

/// The supersampled reference's size for a `width × height` frame: [`SUPERSAMPLE`] times
/// each side, or the largest factor ≥ 1 within [`MAX_FINE_PIXELS`].
pub(crate) fn fine_size(width: u32, height: u32) -> (u32, u32) {
    let pixels = width as u64 * height as u64;
    let mut k = SUPERSAMPLE;
    while k > 1 && pixels * (k as u64 * k as u64) > MAX_FINE_PIXELS {
        k -= 1;
    }
    (width * k, height * k)
}

/// The randomized z-buffer paper's measure of a frame (§4.1: "an image is considered a
/// correct image of the scene if every pixel shows a color which can be found on any triangle
/// fragment visible through that pixel"): the share of pixels covered in `frame` or
/// `reference` whose item is not visible through the pixel. The items visible through a pixel
/// are those of `fine` (the reference drawn at an integer multiple of the frame's size, each
/// pixel's block of subpixels) and the reference's own item at the pixel's centre; no item
/// (the background) is visible through it when one of its subpixels is empty. A window frame
/// and the wall beside it, both in the pixel, are then both right; a sample of a hidden
/// surface is wrong. Subsamples can miss a sliver seen through a pixel, so this overcounts
/// slightly, never undercounts: a triangle no subsample sees counts as wrong. 0 when no pixel
/// is covered.
pub(crate) fn paper_error(frame: &Frame, reference: &Frame, fine: &Frame) -> f64 {
    let verdicts = Verdicts::new(frame, reference, fine);
    let (wrong, covered) = (0..frame.height() as usize)
        .into_par_iter()
        .map(|y| {
            let (mut wrong, mut covered) = (0u64, 0u64);
            for x in 0..frame.width() as usize {
                match verdicts.at(x, y) {
                    Verdict::Empty => {}
                    Verdict::Wrong => (wrong, covered) = (wrong + 1, covered + 1),
                    Verdict::Same | Verdict::Seen => covered += 1,
                }
            }
            (wrong, covered)
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    if covered == 0 {
        0.0
    } else {
        wrong as f64 / covered as f64
    }
}

/// What a pixel of a frame is against the reference, by the paper's criterion
/// ([`paper_error`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Verdict {
    /// Covered in neither frame.
    Empty,
    /// The reference's item.
    Same,
    /// Another item, visible through the pixel: right by the paper's criterion.
    Seen,
    /// An item not visible through the pixel.
    Wrong,
}

/// The per-pixel verdicts of a frame against the reference and its supersampled version.
pub(crate) struct Verdicts<'f> {
    items: &'f [ItemId],
    reference: &'f [ItemId],
    fine: &'f [ItemId],
    width: usize,
    fine_width: usize,
    k: usize,
}

impl<'f> Verdicts<'f> {
    pub(crate) fn new(frame: &'f Frame, reference: &'f Frame, fine: &'f Frame) -> Self {
        let (w, h) = (frame.width() as usize, frame.height() as usize);
        let k = fine.width() as usize / w.max(1);
        debug_assert_eq!(fine.width() as usize, w * k);
        debug_assert_eq!(fine.height() as usize, h * k);
        Self {
            items: frame.items(),
            reference: reference.items(),
            fine: fine.items(),
            width: w,
            fine_width: fine.width() as usize,
            k,
        }
    }

    pub(crate) fn at(&self, x: usize, y: usize) -> Verdict {
        let p = y * self.width + x;
        let (item, truth) = (self.items[p], self.reference[p]);
        if item == NO_ITEM && truth == NO_ITEM {
            return Verdict::Empty;
        }
        if item == truth {
            return Verdict::Same;
        }
        let k = self.k;
        let seen = (0..k).any(|j| {
            let row = (y * k + j) * self.fine_width + x * k;
            self.fine[row..row + k].contains(&item)
        });
        if seen {
            Verdict::Seen
        } else {
            Verdict::Wrong
        }
    }
}

/// The image of where `frame` differs from the reference: pixels wrong by the paper's
/// criterion red, pixels showing another item visible through them yellow, the rest the
/// reference's shaded color (`shaded_reference`) dimmed to a third, uncovered ones black.
pub(crate) fn diff_image(frame: &Frame, reference: &Frame, fine: &Frame, shaded_reference: &Frame) -> image::RgbaImage {
    let verdicts = Verdicts::new(frame, reference, fine);
    let (w, h) = (frame.width(), frame.height());
    let colors = shaded_reference.color();
    image::RgbaImage::from_fn(w, h, |x, y| {
        let c = match verdicts.at(x as usize, y as usize) {
            Verdict::Empty => [0, 0, 0, 255],
            Verdict::Wrong => [255, 0, 0, 255],
            Verdict::Seen => [255, 200, 0, 255],
            Verdict::Same => {
                let c = colors[(y * w + x) as usize];
                [c[0] / 3, c[1] / 3, c[2] / 3, 255]
            }
        };
        image::Rgba(c)
    })
}
