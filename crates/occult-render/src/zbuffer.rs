//! Brute-force z-buffering: every triangle instance of the scene goes to the rasterizer, which
//! clips. The reference every other renderer is held to (DESIGN invariant 2).
//!
//! Cost: O(triangle instances) per frame, whatever is visible. It refuses scenes above
//! [`MAX_BRUTE_FORCE_ITEMS`] triangle instances, where a frame would take hours;
//! `occult-harness`'s `compare` then takes `frustum` as the reference.

use std::sync::Arc;

use occult_core::{Scene, View};
use occult_raster::{Draw, DrawTriangles, Frame, Rasterizer};

use crate::{AlgorithmInfo, FrameStats, Phase, RenderError, RenderOptions, Renderer, Result};

/// Largest scene (in triangle instances) the brute-force renderer accepts.
pub const MAX_BRUTE_FORCE_ITEMS: u64 = 2_000_000_000;

/// Registry entry of [`ZBuffer`] (no settings).
pub static INFO: AlgorithmInfo = AlgorithmInfo {
    name: "zbuffer",
    summary: "brute force: every triangle instance sent to the rasterizer; the reference",
    params: &[],
    counters: &[],
    conservative: true,
    bands: true,
    build: |scene, options, _| Ok(Box::new(ZBuffer::new(scene, options)?)),
};

/// The brute-force renderer.
pub struct ZBuffer {
    scene: Arc<Scene>,
    raster: Rasterizer,
}

impl ZBuffer {
    /// A z-buffer renderer of `scene`.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for a scene above [`MAX_BRUTE_FORCE_ITEMS`]; raster
    /// configuration errors.
    pub fn new(scene: Arc<Scene>, options: &RenderOptions) -> Result<Self> {
        if scene.item_count() > MAX_BRUTE_FORCE_ITEMS {
            return Err(RenderError::BadParameter(format!(
                "zbuffer: the scene has {} triangle instances, more than brute force accepts ({MAX_BRUTE_FORCE_ITEMS}); use a culling renderer as the reference",
                scene.item_count()
            )));
        }
        Ok(Self {
            raster: crate::scene_rasterizer(&scene, options)?,
            scene,
        })
    }
}

impl Renderer for ZBuffer {
    fn name(&self) -> &'static str {
        "zbuffer"
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        let (start, t, mut stats) = crate::begin_frame(&mut self.raster, view, frame)?;
        let mut draws = Vec::new();
        self.scene
            .for_each_mesh_instance(|world_from_object, _, mesh, first_item| {
                if mesh.triangle_count() > 0 {
                    draws.push(Draw {
                        mesh,
                        triangles: DrawTriangles::All,
                        clip_from_object: view.clip_from_object(world_from_object),
                        first_item,
                    });
                }
            });
        stats.phases.add(Phase::Other, t.elapsed());
        // Progress: triangles submitted of the scene's.
        let total = self.scene.item_count();
        crate::rasterize_counted(&mut self.raster, view, frame, &draws, &mut stats, Some((0, total)));
        stats.total = start.elapsed();
        crate::end_frame(&self.raster, stats)
    }

    fn memory_bytes(&self) -> usize {
        self.raster.memory_bytes()
    }

    fn prepare(&mut self, width: u32, height: u32) -> Result<()> {
        crate::prepare_raster(&mut self.raster, &self.scene, width, height);
        Ok(())
    }
}
