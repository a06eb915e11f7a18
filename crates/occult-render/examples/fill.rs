use occult_core::{glam::Affine3A, Camera, Mesh, Vec3, View};
use occult_raster::{Draw, DrawTriangles, Frame, RasterConfig, RasterMode, Rasterizer};
use std::time::Instant;
fn main() {
    let threads: usize = std::env::args().nth(1).map(|s| s.parse().unwrap()).unwrap_or(1);
    let layers: u32 = std::env::args().nth(2).map(|s| s.parse().unwrap()).unwrap_or(1);
    let mut p = vec![];
    let mut t = vec![];
    for l in 0..layers {
        let z = -(l as f32) * 0.01;
        let b = p.len() as u32;
        p.extend([
            Vec3::new(-10.0, -10.0, z),
            Vec3::new(10.0, -10.0, z),
            Vec3::new(10.0, 10.0, z),
            Vec3::new(-10.0, 10.0, z),
        ]);
        t.push([b, b + 1, b + 2]);
        t.push([b, b + 2, b + 3]);
    }
    let mesh = Mesh::new(p, t).unwrap();
    let view = View::new(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO), 1920, 1080).unwrap();
    let mut r = Rasterizer::new(RasterConfig {
        threads,
        ..Default::default()
    })
    .unwrap();
    let mut f = Frame::new(1920, 1080).unwrap();
    let d = Draw {
        mesh: &mesh,
        triangles: DrawTriangles::All,
        clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
        first_item: 0,
    };
    let mut best = f64::MAX;
    for _ in 0..20 {
        r.clear(&mut f);
        let s = Instant::now();
        let c = r.draw(&view, &mut f, std::slice::from_ref(&d), RasterMode::Full);
        best = best.min(s.elapsed().as_secs_f64());
        assert!(c.fragments_written > 0);
    }
    let px = 1920.0 * 1080.0 * layers as f64;
    println!(
        "{} threads, {} layers: {:.2} ms, {:.2} ns/pixel, {:.0} Mpix/s",
        threads,
        layers,
        best * 1e3,
        best * 1e9 / px,
        px / best / 1e6
    );
}
