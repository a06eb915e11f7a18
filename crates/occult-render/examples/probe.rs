use occult_core::{Camera, Mesh, Scene, Vec3, View};
use occult_raster::{Frame, RasterConfig};
use occult_render::{Algorithm, RenderOptions};
use std::sync::Arc;
use std::time::Instant;

fn terrain(g: u32) -> Mesh {
    let h = |x: f32, z: f32| {
        6.0 * (0.07 * x).sin() * (0.05 * z).cos() + 2.0 * (0.31 * x + 0.17 * z).sin() + 0.7 * (1.3 * x - 0.9 * z).cos()
    };
    let mut p = Vec::new();
    for j in 0..=g {
        for i in 0..=g {
            let x = -100.0 + 200.0 * i as f32 / g as f32;
            let z = -100.0 + 200.0 * j as f32 / g as f32;
            p.push(Vec3::new(x, h(x, z), z));
        }
    }
    let mut t = Vec::new();
    for j in 0..g {
        for i in 0..g {
            let a = j * (g + 1) + i;
            t.push([a, a + g + 1, a + 1]);
            t.push([a + 1, a + g + 1, a + g + 2]);
        }
    }
    Mesh::new(p, t).unwrap()
}

fn main() {
    let threads: usize = std::env::args().nth(1).map(|s| s.parse().unwrap()).unwrap_or(1);
    let iters: usize = std::env::args().nth(2).map(|s| s.parse().unwrap()).unwrap_or(20);
    let mesh = terrain(724);
    println!("triangles {}", mesh.triangle_count());
    let scene = Arc::new(Scene::from_mesh("terrain", mesh).unwrap());
    let cam = Camera::look_at(Vec3::new(0.0, 25.0, -110.0), Vec3::ZERO);
    let view = View::new(cam, 1920, 1080).unwrap();
    let opts = RenderOptions {
        raster: RasterConfig {
            threads,
            ..Default::default()
        },
    };
    let mut r = Algorithm::Zbuffer.build(scene.clone(), &opts).unwrap();
    let mut f = Frame::new(1920, 1080).unwrap();
    let s = r.render(&view, &mut f).unwrap();
    println!(
        "covered {:.1}% rasterized {} frags {}",
        f.covered_pixel_count() as f64 / (1920.0 * 1080.0) * 100.0,
        s.triangles_rasterized,
        s.fragments_written
    );
    let mut best = f64::MAX;
    for _ in 0..iters {
        let t = Instant::now();
        r.render(&view, &mut f).unwrap();
        best = best.min(t.elapsed().as_secs_f64());
    }
    println!(
        "threads {threads}: best {:.2} ms, {:.1} Mtri/s",
        best * 1e3,
        1048352.0 / best / 1e6
    );
}
