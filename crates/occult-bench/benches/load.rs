//! Load speed of the file loaders, in MB/s of input on one thread: OBJ, PLY ascii, PLY binary
//! (both byte orders) and GLB, on a mesh of 524,288 triangles (a 512 × 512 height field) that
//! the bench writes with `occult_scenes::save`; and on the real models of `OCCULT_MODELS` when
//! it is set. Files are read into memory first: the figures are parsing and mesh building, not
//! the disk. Goals (issue 25): OBJ and ascii PLY ≥ 100 MB/s, binary PLY and GLB ≥ 1 GB/s.

use std::path::{Path, PathBuf};

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use occult_core::{Mesh, Vec3};
use occult_scenes::load::load_bytes;
use occult_scenes::save::{glb_bytes, obj_bytes, ply_bytes, PlyEncoding};

/// Quads per side of the generated height field.
const GRID: u32 = 512;

/// A height field of `GRID` × `GRID` quads with irregular heights (so that the text formats
/// carry full-length decimals, as scans do).
fn height_field() -> Mesh {
    let side = GRID + 1;
    let positions: Vec<Vec3> = (0..side * side)
        .map(|i| {
            let (x, y) = ((i % side) as f32, (i / side) as f32);
            let h = (x * 0.173).sin() * (y * 0.131).cos() * 7.31 + (i.wrapping_mul(2_654_435_761) % 1000) as f32 * 1e-4;
            Vec3::new(x * 0.25, y * 0.25, h)
        })
        .collect();
    let mut triangles = Vec::with_capacity((2 * GRID * GRID) as usize);
    for y in 0..GRID {
        for x in 0..GRID {
            let i = y * side + x;
            triangles.push([i, i + 1, i + side + 1]);
            triangles.push([i, i + side + 1, i + side]);
        }
    }
    Mesh::new(positions, triangles).expect("valid height field")
}

fn bench_load(c: &mut Criterion, group_name: &str, files: &[(String, PathBuf, Vec<u8>)]) {
    let mut group = c.benchmark_group(group_name);
    group.sample_size(10);
    for (name, path, bytes) in files {
        group.throughput(Throughput::Bytes(bytes.len() as u64));
        group.bench_function(name.as_str(), |b| {
            b.iter(|| load_bytes(path, bytes).expect("the bench's files load"));
        });
    }
    group.finish();
}

fn generated(c: &mut Criterion) {
    let mesh = height_field();
    let files = vec![
        ("obj".to_string(), PathBuf::from("grid.obj"), obj_bytes(&mesh)),
        (
            "ply_ascii".to_string(),
            PathBuf::from("grid.ply"),
            ply_bytes(&mesh, PlyEncoding::Ascii),
        ),
        (
            "ply_binary_le".to_string(),
            PathBuf::from("grid.ply"),
            ply_bytes(&mesh, PlyEncoding::BinaryLittleEndian),
        ),
        (
            "ply_binary_be".to_string(),
            PathBuf::from("grid.ply"),
            ply_bytes(&mesh, PlyEncoding::BinaryBigEndian),
        ),
        ("glb".to_string(), PathBuf::from("grid.glb"), glb_bytes(&mesh)),
    ];
    for (name, _, bytes) in &files {
        eprintln!("load/{name}: {:.1} MB", bytes.len() as f64 / 1e6);
    }
    bench_load(c, "load_grid_524k", &files);
}

/// The real models (OBJ and PLY files directly under each folder of `OCCULT_MODELS`).
fn real_models(c: &mut Criterion) {
    let Some(root) = std::env::var_os("OCCULT_MODELS") else {
        eprintln!("load: OCCULT_MODELS not set; the real models are not measured");
        return;
    };
    let mut files = Vec::new();
    let mut folders: Vec<PathBuf> = std::fs::read_dir(Path::new(&root))
        .map(|entries| entries.flatten().map(|e| e.path()).filter(|p| p.is_dir()).collect())
        .unwrap_or_default();
    folders.sort();
    for folder in folders {
        let Ok(entries) = std::fs::read_dir(&folder) else {
            continue;
        };
        let mut paths: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
        paths.sort();
        for path in paths {
            if occult_scenes::load::Format::from_path(&path).is_some() {
                let bytes = std::fs::read(&path).expect("read model");
                let name = path
                    .file_name()
                    .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
                files.push((name, path, bytes));
            }
        }
    }
    bench_load(c, "load_models", &files);
}

criterion_group!(benches, generated, real_models);
criterion_main!(benches);
