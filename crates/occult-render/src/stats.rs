//! The accounting every renderer returns (DESIGN invariant 4).

use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Duration;

/// A phase of a frame, for time accounting.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Clearing the frame.
    Clear,
    /// Traversing hierarchies and culling.
    Cull,
    /// Transforming, setting up and binning triangles.
    Setup,
    /// Rasterizing triangles into tiles.
    Raster,
    /// Depth queries (boxes, rectangles).
    Query,
    /// Building derived depth structures (pyramids, N-buffers).
    DepthStructure,
    /// Casting rays.
    Rays,
    /// Drawing point samples.
    Samples,
    /// Anything else.
    Other,
}

impl Phase {
    /// The name it serializes as (`depth_structure`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Clear => "clear",
            Self::Cull => "cull",
            Self::Setup => "setup",
            Self::Raster => "raster",
            Self::Query => "query",
            Self::DepthStructure => "depth_structure",
            Self::Rays => "rays",
            Self::Samples => "samples",
            Self::Other => "other",
        }
    }
}

/// Time spent per phase.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PhaseTimes(pub Vec<(Phase, Duration)>);

impl PhaseTimes {
    /// Adds `d` to `phase`.
    pub fn add(&mut self, phase: Phase, d: Duration) {
        match self.0.iter_mut().find(|(p, _)| *p == phase) {
            Some((_, t)) => *t += d,
            None => self.0.push((phase, d)),
        }
    }
    /// Time of `phase` (zero if never added).
    pub fn get(&self, phase: Phase) -> Duration {
        self.0
            .iter()
            .find(|(p, _)| *p == phase)
            .map_or(Duration::ZERO, |(_, t)| *t)
    }
    /// Adds every phase of `other`.
    pub fn merge(&mut self, other: &PhaseTimes) {
        for &(p, d) in &other.0 {
            self.add(p, d);
        }
    }
}

/// Counters particular to one renderer (pyramid tests, queries, ray–triangle tests...), by
/// name, in the order first added; serialized as a JSON object.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Counters(pub Vec<(&'static str, u64)>);

impl Counters {
    /// Adds `n` to counter `name` (created at 0).
    pub fn add(&mut self, name: &'static str, n: u64) {
        match self.0.iter_mut().find(|(k, _)| *k == name) {
            Some((_, v)) => *v += n,
            None => self.0.push((name, n)),
        }
    }
    /// Adds each `(name, n)` of `counts`, in order (as [`Counters::add`] one by one).
    pub fn add_all<const N: usize>(&mut self, counts: [(&'static str, u64); N]) {
        for (name, n) in counts {
            self.add(name, n);
        }
    }
    /// Value of counter `name` (0 if never added).
    pub fn get(&self, name: &str) -> u64 {
        self.0.iter().find(|(k, _)| *k == name).map_or(0, |(_, v)| *v)
    }
    /// Adds every counter of `other`.
    pub fn merge(&mut self, other: &Counters) {
        for &(k, v) in &other.0 {
            self.add(k, v);
        }
    }
}

impl Serialize for Counters {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = serializer.serialize_map(Some(self.0.len()))?;
        for (k, v) in &self.0 {
            map.serialize_entry(k, v)?;
        }
        map.end()
    }
}

impl FrameStats {
    /// The fixed counts as `(field name, value)`, in field order (`triangles_submitted` to
    /// `samples_drawn`).
    pub fn fixed_counters(&self) -> [(&'static str, u64); 10] {
        [
            ("triangles_submitted", self.triangles_submitted),
            ("triangles_rasterized", self.triangles_rasterized),
            ("fragments_written", self.fragments_written),
            ("nodes_visited", self.nodes_visited),
            ("boxes_tested", self.boxes_tested),
            ("boxes_culled", self.boxes_culled),
            ("rects_tested", self.rects_tested),
            ("rects_culled", self.rects_culled),
            ("rays_cast", self.rays_cast),
            ("samples_drawn", self.samples_drawn),
        ]
    }

    /// Time per phase in milliseconds, by [`Phase::name`] (so in name order).
    pub fn phases_ms(&self) -> BTreeMap<&'static str, f64> {
        self.phases
            .0
            .iter()
            .map(|&(p, d)| (p.name(), d.as_secs_f64() * 1e3))
            .collect()
    }

    /// Adds the triangle, fragment, node and box counts of `other` (a part of this frame drawn
    /// apart: a worker's share, a redrawn frame), and its shared rasterization time; counters
    /// and phases are left to the caller.
    pub fn add_counts(&mut self, other: &FrameStats) {
        self.triangles_submitted += other.triangles_submitted;
        self.triangles_rasterized += other.triangles_rasterized;
        self.fragments_written += other.fragments_written;
        self.nodes_visited += other.nodes_visited;
        self.boxes_tested += other.boxes_tested;
        self.boxes_culled += other.boxes_culled;
        self.raster_shared += other.raster_shared;
        self.triangles_shared += other.triangles_shared;
    }

    /// Adds the counts of one rasterizer call.
    pub fn add_raster(&mut self, counts: occult_raster::RasterCounts) {
        self.triangles_submitted += counts.triangles_submitted;
        self.triangles_rasterized += counts.triangles_rasterized;
        self.fragments_written += counts.fragments_written;
        self.triangles_shared += counts.triangles_shared;
    }
}

/// What a renderer did for one frame. Every renderer fills what applies and leaves the rest 0.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FrameStats {
    /// Triangle instances handed to the rasterizer.
    pub triangles_submitted: u64,
    /// Triangles that reached setup and covered at least one pixel centre inside the viewport
    /// (after clipping, back-face and zero-area rejection).
    pub triangles_rasterized: u64,
    /// Fragments that passed the depth test.
    pub fragments_written: u64,
    /// Hierarchy nodes visited.
    pub nodes_visited: u64,
    /// Bounding volumes tested (frustum, occlusion).
    pub boxes_tested: u64,
    /// Bounding volumes culled.
    pub boxes_culled: u64,
    /// Screen rectangles tested against depth.
    pub rects_tested: u64,
    /// Rectangles culled.
    pub rects_culled: u64,
    /// Rays cast.
    pub rays_cast: u64,
    /// Point samples drawn.
    pub samples_drawn: u64,
    /// Total wall time of the frame.
    pub total: Duration,
    /// Wall time per phase.
    pub phases: PhaseTimes,
    /// The part of the [`Phase::Raster`] time spent in draws the rasterizer shared over its
    /// threads (by their share of its triangles): what [`crate::direct`] takes as drawn at a
    /// direct frame's pace. Not reported.
    #[serde(skip)]
    pub raster_shared: Duration,
    /// The triangles of those draws ([`occult_raster::RasterCounts::triangles_shared`]). Not
    /// reported.
    #[serde(skip)]
    pub triangles_shared: u64,
    /// The renderer's own counters.
    pub counters: Counters,
}

/// [`FrameStats`] as reports show it: serializes as an object with the fixed counts
/// ([`FrameStats::fixed_counters`]), `total_ms`, `phases_ms` ([`FrameStats::phases_ms`]) and
/// `counters`, in that order; times in milliseconds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameStatsMs(pub FrameStats);

impl Serialize for FrameStatsMs {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let s = &self.0;
        let mut map = serializer.serialize_map(Some(13))?;
        for (name, v) in s.fixed_counters() {
            map.serialize_entry(name, &v)?;
        }
        map.serialize_entry("total_ms", &(s.total.as_secs_f64() * 1e3))?;
        map.serialize_entry("phases_ms", &s.phases_ms())?;
        map.serialize_entry("counters", &s.counters)?;
        map.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phases_in_milliseconds_by_name() {
        let mut s = FrameStats::default();
        s.phases.add(Phase::DepthStructure, Duration::from_millis(3));
        s.phases.add(Phase::Clear, Duration::from_micros(500));
        let ms: Vec<_> = s.phases_ms().into_iter().collect();
        assert_eq!(ms, [("clear", 0.5), ("depth_structure", 3.0)]);
        assert_eq!(s.fixed_counters().len(), 10);
        assert!(FrameStats::default().phases_ms().is_empty());
    }
}
