//! Color resolution: item ids to Lambert-shaded per-object colors.

use crate::frame::Frame;
use occult_core::{ItemId, Scene, Vec3, View, NO_ITEM};
use rayon::prelude::*;

/// Color of pixels that hold no item.
pub const BACKGROUND: [u8; 4] = [28, 31, 38, 255];

/// Fills `frame`'s colors from its item ids: the triangle's mesh color (or a color hashed from
/// its mesh instance), lit two-sided by a light above and behind the eye (Lambert, with an
/// ambient term). A pure function of (scene, view, items): identical items give identical
/// colors, so comparing items and depth compares images. Colors a renderer resolved itself
/// ([`Frame::resolved_color_mut`]) are kept.
pub fn shade(frame: &mut Frame, scene: &Scene, view: &View) {
    if frame.color_resolved {
        return;
    }
    let light = light_direction(view);
    let width = frame.width() as usize;
    let items = frame.items.clone();
    frame
        .color
        .par_chunks_mut(width)
        .zip(items.par_chunks(width))
        .for_each(|(colors, items)| {
            let mut last: (ItemId, [u8; 4]) = (NO_ITEM, BACKGROUND);
            for (c, &item) in colors.iter_mut().zip(items) {
                if item != last.0 {
                    last = (item, item_color(scene, item, light));
                }
                *c = last.1;
            }
        });
}

/// The light [`shade`] uses for `view` (world space, unit length).
pub fn light_direction(view: &View) -> Vec3 {
    let cam = view.camera();
    let forward = cam.direction();
    let right = forward.cross(cam.up).normalize();
    let up = right.cross(forward);
    (-forward * 0.55 + up * 0.7 + right * 0.45).normalize()
}

/// The color [`shade`] gives a pixel holding `item` under `light` ([`BACKGROUND`] for
/// [`NO_ITEM`] or an id that names no triangle).
pub fn item_color(scene: &Scene, item: ItemId, light: Vec3) -> [u8; 4] {
    let Some(loc) = scene.resolve_item(item) else {
        return BACKGROUND;
    };
    let Some(mesh) = scene.node(loc.mesh_node).mesh() else {
        return BACKGROUND;
    };
    let p = mesh
        .triangle_positions(loc.triangle_index as usize)
        .map(|p| loc.world_from_object.transform_point3(p));
    let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
    let base = mesh
        .triangle_color(loc.triangle_index as usize)
        .unwrap_or_else(|| hashed_color(loc.instance_base));
    let k = 0.3 + 0.7 * n.dot(light).abs();
    [
        (base[0] as f32 * k) as u8,
        (base[1] as f32 * k) as u8,
        (base[2] as f32 * k) as u8,
        255,
    ]
}

/// A pleasant, stable color for an object without one.
fn hashed_color(key: u64) -> [u8; 4] {
    let mut h = key.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    h ^= h >> 29;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 32;
    let c = |s: u32| 110 + ((h >> s) & 0x7f) as u8;
    [c(0), c(8), c(16), 255]
}
