//! Golden frames: hashes of `zbuffer` frames (depth bits, item ids, shaded colors) on a fixed
//! set of generated scenes and views, checked in.
//!
//! Invariant 2 holds every conservative renderer to `zbuffer`, so a change that shifts
//! `zbuffer` and every renderer together (the depth formula, the fill rule, shading, item
//! numbering, a generator) passes every other test. This one catches it.
//!
//! Updating the table is an explicit step: when a change is meant to change frames, run
//! `cargo test --release -p occult-harness --test invariants golden`, paste the table the failure prints
//! over [`GOLDEN`], and say in the commit message why the frames changed.

use std::sync::Arc;

use occult_core::View;
use occult_raster::{shade, Frame};
use occult_render::{Algorithm, RenderOptions};

/// One golden case: a scene spec, a path (`default` is the scene's own camera) and a view of it.
struct Case {
    scene: &'static str,
    path: &'static str,
    view_index: usize,
    width: u32,
    height: u32,
}

/// Covered pixels and the FNV-1a hashes of depth bits, item ids and colors, per case.
type Hashes = (u64, u64, u64, u64);

const CASES: &[Case] = &[
    Case {
        scene: "terrain:g=48",
        path: "default",
        view_index: 0,
        width: 160,
        height: 96,
    },
    Case {
        scene: "city:blocks=2,detail=2",
        path: "street:4",
        view_index: 2,
        width: 160,
        height: 96,
    },
    Case {
        scene: "city:blocks=2,detail=2",
        path: "circle:4",
        view_index: 1,
        width: 96,
        height: 160,
    },
    Case {
        scene: "forest:trees=2,patches=2,levels=1",
        path: "default",
        view_index: 0,
        width: 160,
        height: 96,
    },
    Case {
        scene: "chessboard:n=40",
        path: "default",
        view_index: 0,
        width: 128,
        height: 128,
    },
    Case {
        scene: "plant:units=1,floors=2,pipes=6,sides=6",
        path: "circle:4",
        view_index: 3,
        width: 160,
        height: 96,
    },
    Case {
        scene: "occluder:objects=3",
        path: "default",
        view_index: 0,
        width: 160,
        height: 96,
    },
];

/// The checked-in hashes, in the order of [`CASES`].
const GOLDEN: &[Hashes] = &[
    (8777, 0x63e1f02291090cb3, 0x0a90e950c837d9df, 0x4055839068b1a40f),
    (6580, 0xc12d61221e63a1eb, 0xf8b67df613dfd165, 0x7c5256c59813ff6d),
    (5393, 0xaa4cb5a76b191064, 0xdeebb2c7d3a9f891, 0xcdc8fa370b0a2e93),
    (630, 0x0a67c3de20c052be, 0xae92dee996c6ea37, 0xa383f436f35b9d61),
    (6590, 0x352326cf26e96091, 0x346db7a7166f0df3, 0x74df699a3db0347f),
    (3730, 0x640d090f4a6ca885, 0xa5af2bc87ba694df, 0x1553b9963926ad5d),
    (5400, 0x977b4440c20ceac5, 0xacb938da8af80445, 0x4426dbb102d17785),
];

/// 64-bit FNV-1a: fixed by its definition, unlike std's hashers, so the table stays valid
/// across toolchains.
fn fnv1a(bytes: impl IntoIterator<Item = u8>) -> u64 {
    bytes.into_iter().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

fn render(case: &Case) -> Hashes {
    let built = occult_scenes::spec::parse_spec(case.scene)
        .and_then(|s| s.build())
        .unwrap_or_else(|e| panic!("{}: {e}", case.scene));
    let cameras = if case.path == "default" {
        vec![built.default_camera]
    } else {
        occult_scenes::path::parse_path(case.path, &built.scene, &built.default_camera)
            .unwrap_or_else(|e| panic!("{} {}: {e}", case.scene, case.path))
    };
    let view = View::new(cameras[case.view_index], case.width, case.height)
        .unwrap_or_else(|e| panic!("{} {}: {e}", case.scene, case.path));
    let scene = Arc::new(built.scene);
    let mut zbuffer = Algorithm::ZBUFFER
        .build(Arc::clone(&scene), &RenderOptions::default())
        .unwrap_or_else(|e| panic!("zbuffer on {}: {e}", case.scene));
    let mut frame = Frame::new(case.width, case.height).unwrap_or_else(|e| panic!("frame: {e}"));
    zbuffer
        .render(&view, &mut frame)
        .unwrap_or_else(|e| panic!("zbuffer on {}: {e}", case.scene));
    shade(&mut frame, &scene, &view);
    (
        frame.covered_pixel_count(),
        fnv1a(frame.depth().iter().flat_map(|d| d.to_bits().to_le_bytes())),
        fnv1a(frame.items().iter().flat_map(|i| i.to_le_bytes())),
        fnv1a(frame.color().iter().flatten().copied()),
    )
}

#[test]
fn zbuffer_frames_match_the_checked_in_hashes() {
    let actual: Vec<Hashes> = CASES.iter().map(render).collect();
    for (case, &(covered, ..)) in CASES.iter().zip(&actual) {
        assert!(
            covered > 0,
            "{} {}:{} sees nothing",
            case.scene,
            case.path,
            case.view_index
        );
    }
    if actual != GOLDEN {
        let table: String = actual
            .iter()
            .map(|(c, d, i, k)| format!("    ({c}, {d:#018x}, {i:#018x}, {k:#018x}),\n"))
            .collect();
        panic!(
            "zbuffer frames differ from the golden hashes. If the change is meant to change frames, \
             replace GOLDEN in this file with the table below and say why in the commit message:\n\
             const GOLDEN: &[Hashes] = &[\n{table}];"
        );
    }
}
