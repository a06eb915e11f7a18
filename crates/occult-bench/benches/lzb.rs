//! Local z-buffering (`lzb`): the ray caster's throughput on `terrain` (first-hit rays through
//! the BVH, `caster=bvh`, in packets of 8×8 pixels and one at a time, `packets=off`, and
//! through the octree, `caster=octree`; one thread, every pixel cast: `mode=naive,plane=static,plane_fraction=0.0001,
//! oor=off`), printed as rays per second per thread beside criterion's frame time; and `lzb`
//! frames on `city` along a circle, beside `zbuffer`.
//!
//! With the `embree` feature (Debian's `libembree-dev`), the anchor in the same run: Intel
//! Embree 3 casting the primary rays of the same view (one per pixel centre, in 8×8 tiles)
//! through a BVH of the flattened terrain, one thread, single rays (`rtcIntersect1`) and 4×4
//! packets (`rtcIntersect16`); the rates and occult's over Embree's are printed.
//! `cargo bench -p occult-bench --features embree --bench lzb -- terrain`.

mod common;

use std::sync::Arc;

use criterion::{criterion_group, criterion_main, Criterion};
use occult_core::View;
use occult_raster::{Frame, RasterConfig};
use occult_render::{AlgoSpec, Phase, RenderOptions};

fn one_thread() -> RenderOptions {
    RenderOptions {
        raster: RasterConfig {
            threads: 1,
            ..RasterConfig::default()
        },
        ..RenderOptions::default()
    }
}

fn terrain_rays(c: &mut Criterion) {
    let w = occult_bench::workload("terrain");
    let view = View::new(w.camera, 640, 360).expect("valid view");
    let scene = Arc::new(w.scene);
    let mut rates = Vec::new();
    // The default caster (the BVH, rays in packets of 8×8 pixels), the BVH one ray at a time,
    // and the paper's octree.
    for (caster, settings) in [
        ("bvh", "caster=bvh"),
        ("bvh_single", "caster=bvh,packets=off"),
        ("octree", "caster=octree"),
    ] {
        let spec = AlgoSpec::parse(&format!(
            "lzb:mode=naive,plane=static,plane_fraction=0.0001,oor=off,{settings}"
        ))
        .expect("valid spec");
        let mut r = spec.build(scene.clone(), &one_thread()).expect("renderer builds");
        let mut frame = Frame::new(640, 360).expect("valid size");
        let (mut rays, mut secs) = (0u64, 0f64);
        let mut group = c.benchmark_group("lzb_terrain_640x360");
        group.sample_size(10);
        group.bench_function(format!("naive_rays_1_thread_{caster}"), |b| {
            b.iter(|| {
                let s = r.render(&view, &mut frame).expect("render");
                rays += s.rays_cast;
                secs += s.phases.get(Phase::Rays).as_secs_f64();
            })
        });
        group.finish();
        let rate = rays as f64 / secs;
        eprintln!(
            "lzb ray caster ({caster}) on terrain: {:.2} Mrays/s per thread ({rays} rays in {secs:.3} s of the rays phase)",
            rate / 1e6
        );
        rates.push(rate);
    }
    #[cfg(feature = "embree")]
    anchor::embree_terrain(c, &view, rates[0]);
}

fn city_circle(c: &mut Criterion) {
    common::bench_path(
        c,
        "city_circle8_512x512".into(),
        "city",
        "circle:8",
        (512, 512),
        // The paper's algorithm alone: with payoff, frames it loses are drawn as frustum does.
        &["zbuffer", "lzb:payoff=off"],
    );
}

criterion_group!(benches, terrain_rays, city_circle);
criterion_main!(benches);

/// Intel Embree on the same primary rays (feature `embree`).
#[cfg(feature = "embree")]
mod anchor {
    use std::time::Instant;

    use criterion::Criterion;
    use embree3::{
        BufferUsage, Device, Format, GeometryKind, Hit16, IntersectContext, Ray, Ray16, RayHit, RayHit16, ValidMask,
        ValidMaskN,
    };
    use occult_core::{Vec3, Vec4, View};

    /// The ray of every pixel centre of `view` (origin, direction through the pixel), in 8×8
    /// tiles as lzb casts them.
    fn primary_rays(view: &View) -> Vec<([f32; 3], [f32; 3])> {
        let world_from_clip = view.clip_from_world().inverse();
        let eye = view.camera().eye;
        let (w, h) = (view.width(), view.height());
        let mut rays = Vec::with_capacity((w * h) as usize);
        for ty in (0..h).step_by(8) {
            for tx in (0..w).step_by(8) {
                for y in ty..(ty + 8).min(h) {
                    for x in tx..(tx + 8).min(w) {
                        let nx = (x as f32 + 0.5) / w as f32 * 2.0 - 1.0;
                        let ny = 1.0 - (y as f32 + 0.5) / h as f32 * 2.0;
                        let p = world_from_clip * Vec4::new(nx, ny, 0.5, 1.0);
                        let d: Vec3 = p.truncate() / p.w - eye;
                        rays.push((eye.to_array(), d.normalize().to_array()));
                    }
                }
            }
        }
        rays
    }

    pub fn embree_terrain(c: &mut Criterion, view: &View, occult_rate: f64) {
        let w = occult_bench::workload("terrain");
        let mesh = w.scene.flatten(u64::MAX).expect("terrain flattens");
        let device = Device::new().expect("Embree device");
        let mut scene = device.create_scene().expect("Embree scene");
        let mut geometry = device.create_geometry(GeometryKind::TRIANGLE).expect("Embree geometry");
        let positions: Vec<[f32; 3]> = mesh.positions().iter().map(|p| p.to_array()).collect();
        geometry
            .set_new_buffer::<[f32; 3]>(BufferUsage::VERTEX, 0, Format::FLOAT3, 12, positions.len())
            .expect("vertex buffer")
            .copy_from_slice(&positions);
        geometry
            .set_new_buffer::<[u32; 3]>(BufferUsage::INDEX, 0, Format::UINT3, 12, mesh.triangles().len())
            .expect("index buffer")
            .copy_from_slice(mesh.triangles());
        let geometry = geometry.commit();
        scene.attach_geometry(&geometry);
        let t = Instant::now();
        scene.commit();
        let build = t.elapsed();
        let rays = primary_rays(view);
        let single = |hits: &mut u64| {
            let mut ctx = IntersectContext::coherent();
            for (o, d) in &rays {
                let mut rh = RayHit::from_ray(Ray::new(*o, *d, 0.0, f32::INFINITY, 0.0, u32::MAX, 0));
                scene.intersect(&mut ctx, &mut rh);
                *hits += (rh.hit.geomID != u32::MAX) as u64;
            }
        };
        // 4×4 packets: each 8×8 tile as four 4×4 quarters.
        let packets = |hits: &mut u64| {
            let mut ctx = IntersectContext::coherent();
            for tile in rays.chunks(64) {
                for quarter in 0..4 {
                    let mut p = RayHit16 {
                        ray: Ray16::default(),
                        hit: Hit16::new(),
                    };
                    let mut valid = ValidMaskN::<16>::all_active();
                    for lane in 0..16 {
                        let (row, col) = ((quarter / 2) * 4 + lane / 4, (quarter % 2) * 4 + lane % 4);
                        match tile.get(row * 8 + col) {
                            Some((o, d)) => {
                                (p.ray.org_x[lane], p.ray.org_y[lane], p.ray.org_z[lane]) = (o[0], o[1], o[2]);
                                (p.ray.dir_x[lane], p.ray.dir_y[lane], p.ray.dir_z[lane]) = (d[0], d[1], d[2]);
                            }
                            None => valid.lanes_mut()[lane] = ValidMask::Invalid,
                        }
                    }
                    scene.intersect16(&mut ctx, &mut p, &valid);
                    *hits += (0..16)
                        .filter(|&l| valid.lanes_mut()[l] == ValidMask::Valid && p.hit.geomID[l] != u32::MAX)
                        .count() as u64;
                }
            }
        };
        // Both ways must hit the same: the rays are real (a view of the terrain hits almost all).
        let (mut single_hits, mut packet_hits) = (0, 0);
        single(&mut single_hits);
        packets(&mut packet_hits);
        assert_eq!(single_hits, packet_hits, "single rays and packets hit alike");
        let mut group = c.benchmark_group("embree_terrain_640x360");
        group.sample_size(10);
        let mut rates = [0f64; 2];
        for (k, (name, cast)) in [
            ("single_rays_1_thread", &single as &dyn Fn(&mut u64)),
            ("packets16_1_thread", &packets),
        ]
        .into_iter()
        .enumerate()
        {
            let (mut n, mut secs) = (0u64, 0f64);
            group.bench_function(name, |b| {
                b.iter(|| {
                    let mut hits = 0;
                    let t = Instant::now();
                    cast(&mut hits);
                    secs += t.elapsed().as_secs_f64();
                    n += rays.len() as u64;
                    hits
                })
            });
            rates[k] = n as f64 / secs;
        }
        group.finish();
        eprintln!(
            "Embree 3 on the same view ({} rays, {single_hits} hitting, BVH of {} triangles built in {:.2} s): single rays {:.2} Mrays/s, 16-ray packets {:.2} Mrays/s per thread",
            rays.len(),
            mesh.triangle_count(),
            build.as_secs_f64(),
            rates[0] / 1e6,
            rates[1] / 1e6,
        );
        if occult_rate.is_finite() {
            eprintln!(
                "occult's caster (bvh, packets) over Embree's, same run: {:.3}x single rays, {:.3}x packets",
                occult_rate / rates[0],
                occult_rate / rates[1]
            );
        }
    }
}
