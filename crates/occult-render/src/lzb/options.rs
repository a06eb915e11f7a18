//! `lzb`'s registry entry, its parameters and their checks.

use super::{Lzb, MAX_DEPTH};
use crate::{AlgorithmInfo, ParamDoc, Params, RenderError, Result};

/// The registry entry of `lzb`.
pub static INFO: AlgorithmInfo = AlgorithmInfo {
    name: "lzb",
    summary: "local z-buffering: near z-buffer + lazy/selective/object-oriented ray casting to a PVL (Han & Zeiger)",
    params: &[
        ParamDoc {
            key: "leaf",
            default: "auto",
            help: "max triangles per mesh octree leaf (>= 1; §II.A, the paper's Octree-o used 150), or auto: 150 with caster=octree (whose rays walk the octree's leaves), else the scene's triangle instances / 16384, at least 150 and at most 16384 (a frame's work per leaf in view stays bounded on scenes of tens of millions of triangles; not in the paper)",
        },
        ParamDoc {
            key: "depth",
            default: "10",
            help: "max octree depth (0..=24; §II.A)",
        },
        ParamDoc {
            key: "caster",
            default: "bvh",
            help: "what the rays walk in a mesh: bvh (an 8-wide SAH BVH per unique mesh, one reference per triangle, leaves of up to bvh_leaf triangles; not in the paper; the default: naive first-hit rays are 2.5x faster through it, and pvl=hits needs it) or octree (the paper's octree of §II.A, whose leaves make the PVL; pvl= then defaults to leaves, the paper's; also the default with pvl=leaves or pvl=triangles in lazy mode, whose one-at-a-time cone rays are faster through it)",
        },
        ParamDoc {
            key: "bvh_leaf",
            default: "8",
            help: "max triangles per BVH leaf, 1..=8 (the lanes of one triangle test: the build counts a leaf's cost in tests of 8, so leaves fill up to this size); needs caster=bvh (refused with caster=octree)",
        },
        ParamDoc {
            key: "packets",
            default: "on",
            help: "rays of up to 64 neighbouring pixels (8x8 tiles) cast together: one packet through each mesh's BVH, each ray tested as alone, one cone through a group's octree (not in the paper); on by default in naive mode and with pvl=hits, and needs one of them and caster=bvh (refused otherwise: lazy rays that record leaves go one at a time); off: one ray at a time",
        },
        ParamDoc {
            key: "group_leaf",
            default: "8",
            help: "max instances per group octree leaf (>= 1)",
        },
        ParamDoc {
            key: "mode",
            default: "lazy",
            help: "lazy: rays build a PVL drawn by the z-buffer (§III.A, exact); naive: rays shade first hits (§II, approximate)",
        },
        ParamDoc {
            key: "select",
            default: "hybrid",
            help: "local occluders tested per leaf: all (§III.A), static (k largest, §III.B.1), dynamic (visibility, §III.B.2), hybrid; for rays that record leaves or their triangles: needs pvl=leaves or pvl=triangles (refused with pvl=hits, whose rays test every triangle of a leaf they reach)",
        },
        ParamDoc {
            key: "k",
            default: "5",
            help: "local occluders per leaf for select=static|hybrid (>= 1; needs pvl=leaves or pvl=triangles)",
        },
        ParamDoc {
            key: "base_cos",
            default: "0.5",
            help: "preset |v.n| of the base visibility (x mean leaf area) for select=dynamic|hybrid, in [0, 1] (needs pvl=leaves or pvl=triangles)",
        },
        ParamDoc {
            key: "plane",
            default: "cost",
            help: "partition plane: static (plane_fraction of the depth), dynamic (coarse rays' mean hit distance, §II.B) or cost (the plane whose near rasterization and rays are expected to cost least, from the coarse rays' hits, the leaves' triangles and last frame's rates; the default in lazy mode, dynamic in naive mode)",
        },
        ParamDoc {
            key: "plane_fraction",
            default: "0.2",
            help: "static plane depth as a fraction of the frustum depth over the scene, in (0, 1]",
        },
        ParamDoc {
            key: "coarse_rays",
            default: "256",
            help: "rays of the dynamic plane's coarse ray casting, 1..=65536",
        },
        ParamDoc {
            key: "plane_reuse",
            default: "8",
            help: "frames a dynamic plane is reused while the camera moves little (>= 1; 1 = every frame)",
        },
        ParamDoc {
            key: "oor",
            default: "on",
            help: "object-oriented ray casting: rays only inside the screen polygons of far leaves (§III.C)",
        },
        ParamDoc {
            key: "pvl",
            default: "hits",
            help: "what a lazy ray records: hits (the triangles the ray's cone of 1/64 pixel may touch before its bound: triangle-exact; the rays go in packets: needs caster=bvh and packets=on, the defaults; every triangle a ray reaches may end it, so select=, k=, base_cos= and coherence= are refused; not in the paper; the default unless caster=octree), leaves (§III.A, every leaf on its path; the default with caster=octree) or triangles (those of the path's leaves whose box the ray's cone enters before its bound)",
        },
        ParamDoc {
            key: "coherence",
            default: "on",
            help: "start each ray from its neighbour's hit (§III.D); for rays cast one at a time: needs pvl=leaves or pvl=triangles (pvl=hits casts packets)",
        },
        ParamDoc {
            key: "near_cull",
            default: "on",
            help: "draw the near set front to back in growing batches, testing each near leaf (or mesh) against the depth drawn so far through a pyramid, as hzb does, and skipping the hidden ones (not in the paper; off: one draw, §II)",
        },
        ParamDoc {
            key: "near_temporal",
            default: "on",
            help: "near_cull=on: draw the near leaves that showed a pixel in the last frame first, untested, so that the rest is tested against nearly the frame's final depth (hzb's visible list, by leaves; not in the paper; needs near_cull=on, and is off with near_cull=off)",
        },
        ParamDoc {
            key: "far_cull",
            default: "on",
            help: "after the near pass, drop the far leaves hidden behind what it drew (an instance's far leaves tested as one box, through a pyramid of the near depth), so that object-oriented ray casting neither projects them nor casts their pixels (not in the paper; needs oor=on, and is off with oor=off)",
        },
        ParamDoc {
            key: "payoff",
            default: "on",
            help: "give up a frame whose rays would take longer than drawing it directly (its rest then drawn directly), and draw runs of frames as frustum does while lzb frames are slower than such direct frames (not in the paper; lazy mode only: off, and refused, with mode=naive, whose frames are approximate)",
        },
    ],
    counters: &[
        "octree_leaf",
        "plane_reused",
        "coarse_rays",
        "near_leaves",
        "far_leaves",
        "near_triangles",
        "oor_polygons",
        "oor_instances_skipped",
        "rays",
        "ray_tri_tests",
        "ray_leaves_visited",
        "ray_nodes_visited",
        "coherent_starts",
        "rays_resolved",
        "unfinished_pixels",
        "z_clip_permille_of_far",
        "pvl_leaves",
        "pvl_entries_triangles",
        "pvl_triangles",
        "near_culled_units",
        "near_culled_groups",
        "near_culled_triangles",
        "near_visible_triangles",
        "near_borrowed_triangles",
        "far_culled_leaves",
        "far_direct_triangles",
        crate::payoff::COUNTERS[0],
        crate::payoff::COUNTERS[1],
        crate::direct::COUNTER,
        crate::direct::SCREENED,
    ],
    conservative: true,
    bands: false,
    build: |scene, options, params| Ok(Box::new(Lzb::new(scene, options, &LzbOptions::from_params(params)?)?)),
};

/// What the rays do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Rays record their paths into a PVL drawn by the z-buffer (§III.A).
    Lazy,
    /// Rays shade their first hits (§II): approximate.
    Naive,
}

/// How the partition plane is chosen (§II.B).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Plane {
    /// At `plane_fraction` of the depth over which the scene lies in the frustum.
    Static,
    /// At the mean first-hit distance of coarse rays (the paper's dynamic plane).
    Dynamic,
    /// Where the near pass and the rays are expected to cost least ([`cost_plane`]).
    Cost,
}

/// Which triangles of a leaf a ray tests (§III.B).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Selection {
    /// All of them (lazy ray casting, §III.A).
    All,
    /// The `k` largest (Octree-o).
    Static,
    /// Those whose visibility exceeds the leaf's base visibility.
    Dynamic,
    /// The `k` largest, filtered by visibility.
    Hybrid,
}

/// What the rays walk in a mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CasterKind {
    /// An 8-wide BVH per unique mesh ([`occult_spatial::RayBvh`]); the PVL holds the
    /// triangles of the BVH leaves on the ray paths.
    Bvh,
    /// The mesh's octree (§II.A); the PVL holds octree leaves.
    Octree,
}

/// Tunables of [`Lzb`] (see [`INFO`] for each one's meaning and paper section).
#[derive(Clone, Debug, PartialEq)]
pub struct LzbOptions {
    /// Max triangles per mesh octree leaf; `None`: chosen for the scene
    /// ([`LzbOptions::leaf_size`]).
    pub leaf: Option<usize>,
    /// Max octree depth.
    pub depth: u32,
    /// Max instances per group octree leaf.
    pub group_leaf: usize,
    /// What the rays walk in a mesh.
    pub caster: CasterKind,
    /// Max triangles per BVH leaf (`caster=bvh`).
    pub bvh_leaf: usize,
    /// Rays cast in packets of neighbouring pixels (`caster=bvh`; `mode=naive` or `pvl=hits`).
    pub packets: bool,
    /// Ray mode.
    pub mode: Mode,
    /// Occluder selection.
    pub selection: Selection,
    /// Occluders per leaf.
    pub k: usize,
    /// Preset `|v·n|` of the base visibility.
    pub base_cos: f32,
    /// How the partition plane is chosen.
    pub plane: Plane,
    /// Static plane fraction.
    pub plane_fraction: f32,
    /// Coarse rays of the dynamic plane.
    pub coarse_rays: u32,
    /// Frames a dynamic plane is reused.
    pub plane_reuse: u32,
    /// Object-oriented ray casting.
    pub oor: bool,
    /// Coherence start.
    pub coherence: bool,
    /// What a lazy ray records.
    pub pvl: Pvl,
    /// Give up frames whose rays do not pay, and draw frames directly while they do not
    /// (lazy mode only).
    pub payoff: bool,
    /// Occlusion-cull the near set front to back (not in the paper).
    pub near_cull: bool,
    /// Draw last frame's visible near leaves first, untested (not in the paper; needs
    /// `near_cull`).
    pub near_temporal: bool,
    /// Drop the far leaves hidden behind the near set before object-oriented ray casting
    /// (not in the paper; needs `oor`).
    pub far_cull: bool,
}

/// What a lazy ray records into the PVL.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pvl {
    /// Every leaf on its path (§III.A).
    Leaves,
    /// The triangles of those leaves whose box its cone enters before its bound.
    Triangles,
    /// The triangles its cone may touch before its bound (triangle-exact).
    Hits,
}

impl Default for LzbOptions {
    fn default() -> Self {
        Self::from_params(&Params::new("lzb")).expect("defaults are valid")
    }
}

/// The paper's most triangles per octree leaf (Octree-o, §II.A), and `leaf=auto`'s least.
pub const PAPER_LEAF: usize = 150;
/// Full leaves `leaf=auto` cuts a scene's triangle instances into (each instance's leaves
/// counted; leaves are seldom full, so a view from outside holds several times this many):
/// a frame's work per leaf in view (the frustum walk, the near/far split, the cost plane, the
/// object-oriented polygons, the near pass's units) then stays bounded however large the
/// scene. On `city:blocks=32` (29.5 M), 150 → 1,799 triangles a leaf took the suite's
/// `city32-street` from 5.45× to 6.33× `zbuffer` and `city32-orbit` from 0.92× to 1.12×
/// (docs/lzb.md).
pub const AUTO_LEAF_BUDGET: u64 = 16_384;
/// `leaf=auto`'s most triangles per leaf.
pub const AUTO_LEAF_MAX: usize = 16_384;

/// `leaf=auto`'s leaf size for a scene of `items` triangle instances where the rays do not walk
/// the octree: `items / AUTO_LEAF_BUDGET` rounded up, within `PAPER_LEAF..=AUTO_LEAF_MAX`.
pub fn auto_leaf(items: u64) -> usize {
    usize::try_from(items.div_ceil(AUTO_LEAF_BUDGET))
        .unwrap_or(AUTO_LEAF_MAX)
        .clamp(PAPER_LEAF, AUTO_LEAF_MAX)
}

impl LzbOptions {
    /// Most triangles per mesh octree leaf for `scene`: [`LzbOptions::leaf_size_for`] of its
    /// triangle instances.
    pub fn leaf_size(&self, scene: &occult_core::Scene) -> usize {
        self.leaf_size_for(scene.item_count())
    }

    /// Most triangles per mesh octree leaf for a scene of `items` triangle instances: `leaf=N`
    /// as given; `leaf=auto`, the paper's 150 where the rays walk the octree
    /// (`caster=octree`: naive rays test every triangle of the leaves they reach, lazy ones
    /// make the PVL of them), else [`auto_leaf`] (`caster=bvh`: the rays walk each mesh's BVH,
    /// and the PVL is made of its leaves or of triangles whatever the octree's leaves).
    pub fn leaf_size_for(&self, items: u64) -> usize {
        match self.leaf {
            Some(n) => n,
            None if self.caster == CasterKind::Octree => PAPER_LEAF,
            None => auto_leaf(items),
        }
    }

    /// Reads and checks the settings.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] naming the key for values out of range.
    pub fn from_params(p: &Params) -> Result<Self> {
        let mode = match p.choice("mode", &["lazy", "naive"], "lazy")? {
            "naive" => Mode::Naive,
            _ => Mode::Lazy,
        };
        // The triangle-exact PVL unless the paper's octree is asked for, whose leaves are the
        // paper's PVL (and whose cone rays go one at a time).
        let octree = p.raw("caster").is_some_and(|c| c.trim().eq_ignore_ascii_case("octree"));
        let pvl_default = if mode == Mode::Lazy && !octree {
            "hits"
        } else {
            "leaves"
        };
        let pvl = match p.choice("pvl", &["leaves", "triangles", "hits"], pvl_default)? {
            "triangles" => Pvl::Triangles,
            "hits" => Pvl::Hits,
            _ => Pvl::Leaves,
        };
        let o = Self {
            leaf: match p.raw("leaf").map(str::trim) {
                None => None,
                Some(v) if v.eq_ignore_ascii_case("auto") => None,
                Some(v) => Some(v.parse().map_err(|_| {
                    RenderError::BadParameter(format!("lzb: leaf={v}: expected auto or a number of triangles"))
                })?),
            },
            depth: p.get("depth", 10u32)?,
            group_leaf: p.get("group_leaf", 8usize)?,
            // Measured (docs/lzb.md): the BVH's thin first-hit rays are faster; of rays that
            // record leaves, the octree's cone rays (with `select=`'s few tests per large leaf)
            // are; `pvl=hits` casts through the BVH.
            caster: match p.choice(
                "caster",
                &["bvh", "octree"],
                if mode == Mode::Lazy && pvl != Pvl::Hits {
                    "octree"
                } else {
                    "bvh"
                },
            )? {
                "octree" => CasterKind::Octree,
                _ => CasterKind::Bvh,
            },
            bvh_leaf: p.get("bvh_leaf", 8usize)?,
            packets: false,
            mode,
            selection: match p.choice("select", &["all", "static", "dynamic", "hybrid"], "hybrid")? {
                "all" => Selection::All,
                "static" => Selection::Static,
                "dynamic" => Selection::Dynamic,
                _ => Selection::Hybrid,
            },
            k: p.get("k", 5usize)?,
            base_cos: p.get("base_cos", 0.5f32)?,
            // The cost model weighs lazy rays and their PVL; naive rays shade, as §II measures.
            plane: match p.choice(
                "plane",
                &["static", "dynamic", "cost"],
                if mode == Mode::Lazy { "cost" } else { "dynamic" },
            )? {
                "static" => Plane::Static,
                "cost" => Plane::Cost,
                _ => Plane::Dynamic,
            },
            plane_fraction: p.get("plane_fraction", 0.2f32)?,
            coarse_rays: p.get("coarse_rays", 256u32)?,
            plane_reuse: p.get("plane_reuse", 8u32)?,
            oor: p.flag("oor", true)?,
            coherence: p.flag("coherence", true)?,
            pvl,
            payoff: p.flag("payoff", mode == Mode::Lazy)?,
            near_cull: p.flag("near_cull", true)?,
            near_temporal: false,
            far_cull: false,
        };
        let o = Self {
            near_temporal: p.flag("near_temporal", o.near_cull)?,
            packets: p.flag(
                "packets",
                (o.mode == Mode::Naive || o.pvl == Pvl::Hits) && o.caster == CasterKind::Bvh,
            )?,
            far_cull: p.flag("far_cull", o.oor)?,
            ..o
        };
        if o.mode == Mode::Lazy && o.pvl == Pvl::Hits {
            if let Some(key) = ["select", "k", "base_cos", "coherence"]
                .into_iter()
                .find(|k| p.raw(k).is_some())
            {
                return Err(RenderError::BadParameter(format!(
                    "lzb: {key}= sets up rays that record leaves one ray at a time; pvl=hits (the default \
                     unless caster=octree) casts packets that test every triangle they reach: add \
                     pvl=leaves (or caster=octree, the paper's)"
                )));
            }
        }
        if p.raw("bvh_leaf").is_some() && o.caster == CasterKind::Octree {
            return Err(RenderError::BadParameter(
                "lzb: bvh_leaf sizes the leaves of the BVH of caster=bvh, which these rays do not walk \
                 (caster=octree, asked for or the default with pvl=leaves|triangles in lazy mode): \
                 add caster=bvh"
                    .into(),
            ));
        }
        o.check()?;
        Ok(o)
    }

    pub(super) fn check(&self) -> Result<()> {
        let bad = |m: String| Err(RenderError::BadParameter(format!("lzb: {m}")));
        if self.leaf == Some(0) {
            return bad("leaf=0: an octree leaf must hold at least 1 triangle".into());
        }
        if self.depth > MAX_DEPTH {
            return bad(format!("depth={} exceeds {MAX_DEPTH}", self.depth));
        }
        if !(1..=occult_spatial::MAX_BVH_LEAF).contains(&self.bvh_leaf) {
            return bad(format!(
                "bvh_leaf={} is not in 1..={}",
                self.bvh_leaf,
                occult_spatial::MAX_BVH_LEAF
            ));
        }
        if self.group_leaf == 0 {
            return bad("group_leaf=0: a group leaf must hold at least 1 instance".into());
        }
        if self.k == 0 {
            return bad("k=0: a leaf needs at least 1 local occluder".into());
        }
        if !(0.0..=1.0).contains(&self.base_cos) {
            return bad(format!("base_cos={} is not in [0, 1]", self.base_cos));
        }
        if !(self.plane_fraction > 0.0 && self.plane_fraction <= 1.0) {
            return bad(format!(
                "plane_fraction={} puts the partition plane outside the frustum (must be in (0, 1])",
                self.plane_fraction
            ));
        }
        if self.coarse_rays == 0 || self.coarse_rays > 65536 {
            return bad(format!("coarse_rays={} is not in 1..=65536", self.coarse_rays));
        }
        if self.plane_reuse == 0 {
            return bad("plane_reuse=0: a plane is used for at least 1 frame".into());
        }
        if self.far_cull && !self.oor {
            return bad(
                "far_cull=on drops hidden far leaves from object-oriented ray casting, which oor=off turns off (every unfinished pixel is then cast): it needs oor=on".into(),
            );
        }
        if self.near_temporal && !self.near_cull {
            return bad(
                "near_temporal=on orders the near pass's occlusion tests, which near_cull=off turns off (the near set is then one draw): it needs near_cull=on".into(),
            );
        }
        if self.packets && (self.mode != Mode::Naive && self.pvl != Pvl::Hits || self.caster != CasterKind::Bvh) {
            return bad(
                "packets=on casts naive first-hit rays or pvl=hits cones through the BVH: it needs mode=naive or pvl=hits, and caster=bvh (their default)"
                    .into(),
            );
        }
        if self.pvl == Pvl::Hits && (self.mode != Mode::Lazy || self.caster != CasterKind::Bvh || !self.packets) {
            return bad(
                "pvl=hits records what lazy rays cast in packets through the BVH may touch: it needs mode=lazy, caster=bvh and packets=on (its defaults)"
                    .into(),
            );
        }
        if self.payoff && self.mode == Mode::Naive {
            return bad(
                "payoff=on needs mode=lazy: naive frames are approximate, and drawing them directly would change them"
                    .into(),
            );
        }
        Ok(())
    }
}
