//! Wavefront OBJ with MTL material libraries.
//!
//! # References
//! - Wavefront Technologies, *Object Files (.obj)*, Advanced Visualizer manual, appendix B1:
//!   the `v`, `f`, `o`, `g`, `usemtl` and `mtllib` statements; 1-based and negative (relative)
//!   vertex references.
//! - Wavefront Technologies, *Material Library Files (.mtl)*, Advanced Visualizer manual:
//!   `newmtl`, `Kd` and the texture map statements (`map_Kd`, `map_Ka`, `bump`, ...).
//!
//! Read: `v x y z` (a fourth value, `w` or a vertex color, is ignored), `f` with `v`, `v/vt`,
//! `v//vn` or `v/vt/vn` corners, `o` / `g` (start an object), `usemtl`, `mtllib`; `#` starts a
//! comment; CRLF line ends are accepted. Ignored, as most readers do: `vt`, `vn`, `vp`, `s`,
//! `l`, `p` (counted in a warning), free-form curves and surfaces, unknown statements.
//!
//! Every (`o`/`g` object, `usemtl` material) pair becomes one mesh (an object named twice is one
//! object), its polygons fan-triangulated (`p0 p1 p2`, `p0 p2 p3`, ...), holding only the
//! vertices it uses, and colored by the material's diffuse `Kd` (taken as 8-bit sRGB as
//! written, without conversion).
//!
//! Errors are reported as `file.obj line N: ...`. A vertex reference may point forward (to a `v`
//! defined later in the file); references are checked once the whole file is read.
//!
//! Warnings (one line per kind, with a count and the first line): faces with fewer than three
//! corners (skipped, as other readers do; their corners are still checked, so `f 0 1` or an
//! index past the last vertex is an error all the same), `p` and `l` statements, material
//! libraries that cannot be read, materials no library defines, unreadable `Kd` lines and
//! missing texture files.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use occult_core::{MeshColors, Rgba8, Vec3};

use super::{compact_mesh, fan_triangulate, file_stem, quoted, read_bytes, scene_of_meshes, unit_to_u8};
use super::{Disk, ExternalFiles, LoadError, LoadedScene, Location, WarningKind, Warnings, SHORT_FACE};

/// Textures named in a warning before "and N more".
const LISTED_NAMES_MAX: usize = 5;

const POINT_OR_LINE: WarningKind = WarningKind {
    one: "a point or line statement ignored",
    many: "point and line statements ignored",
};
const LIBRARY_NOT_READ: WarningKind = WarningKind {
    one: "a material library not read; meshes using it get no color",
    many: "material libraries not read; meshes using them get no color",
};
const UNDEFINED_MATERIALS: WarningKind = WarningKind {
    one: "materials used but not defined in any material library",
    many: "materials used but not defined in any material library",
};
const DIFFUSE_NOT_READ: WarningKind = WarningKind {
    one: "a diffuse color not read",
    many: "diffuse colors not read",
};
const MISSING_TEXTURES: WarningKind = WarningKind {
    one: "a texture file not found (textures are not used)",
    many: "texture files not found (textures are not used)",
};

/// Loads a Wavefront OBJ file and the `.mtl` libraries it names (relative to its folder).
///
/// Missing or unreadable `.mtl` files, missing textures and undefined materials are warnings in
/// [`LoadedScene::warnings`]; the meshes concerned get no color.
///
/// # Errors
/// [`LoadError::Io`] when the file cannot be read; [`LoadError::Parse`] for a malformed `v` or
/// `f` statement (with the line); [`LoadError::IndexOutOfRange`] for a face corner naming a vertex
/// that does not exist (index 0, a relative index before the first vertex, or past the last);
/// [`LoadError::NonFinite`] for a NaN or infinite coordinate (also one that overflows `f32`);
/// [`LoadError::Empty`] when the file has no face.
pub fn load_obj(path: &Path) -> Result<LoadedScene, LoadError> {
    obj_from_bytes(path, &read_bytes(path)?, &Disk)
}

/// [`load_obj`] of bytes in memory; `path` names them and locates the `.mtl` files, which are
/// read from `files`.
pub(super) fn obj_from_bytes(path: &Path, data: &[u8], files: &dyn ExternalFiles) -> Result<LoadedScene, LoadError> {
    let mut reader = ObjReader::new(path);
    reader.parse(data)?;
    reader.finish(files)
}

/// The triangles of one (object, material) pair, with global vertex indices.
struct Chunk {
    object_index: usize,
    material_index: Option<usize>,
    triangles: Vec<[u32; 3]>,
}

/// A forward vertex reference, checked at the end of the file.
#[derive(Clone, Copy)]
struct ForwardReference {
    index: u32,
    written: i64,
    line: u64,
}

/// One pass over an OBJ file.
struct ObjReader<'p> {
    path: &'p Path,
    positions: Vec<Vec3>,
    object_names: Vec<String>,
    object_index_by_name: HashMap<String, usize>,
    material_names: Vec<String>,
    material_index_by_name: HashMap<String, usize>,
    chunks: Vec<Chunk>,
    chunk_by_key: HashMap<(usize, Option<usize>), usize>,
    object_index: usize,
    material_index: Option<usize>,
    chunk_index: Option<usize>,
    libraries: Vec<(String, u64)>,
    /// The largest reference past the vertices defined at the time.
    forward: Option<ForwardReference>,
    corners: Vec<u32>,
    ignored_point_and_line_count: u64,
    short_face_count: u64,
    warnings: Warnings,
}

impl<'p> ObjReader<'p> {
    fn new(path: &'p Path) -> Self {
        Self {
            path,
            positions: Vec::new(),
            object_names: vec![file_stem(path)],
            object_index_by_name: HashMap::from([(file_stem(path), 0)]),
            material_names: Vec::new(),
            material_index_by_name: HashMap::new(),
            chunks: Vec::new(),
            chunk_by_key: HashMap::new(),
            object_index: 0,
            material_index: None,
            chunk_index: None,
            libraries: Vec::new(),
            forward: None,
            corners: Vec::new(),
            ignored_point_and_line_count: 0,
            short_face_count: 0,
            warnings: Warnings::default(),
        }
    }

    fn parse_error(&self, line: u64, message: String) -> LoadError {
        LoadError::Parse {
            path: self.path.to_path_buf(),
            location: Location::Line(line),
            message,
        }
    }

    fn parse(&mut self, data: &[u8]) -> Result<(), LoadError> {
        for (line_index, line) in statement_lines(data) {
            let line_number = line_index as u64 + 1;
            let mut tokens = tokens_of(line);
            let Some(keyword) = tokens.next() else { continue };
            // What follows the keyword, for statements that take a name.
            let rest = || String::from_utf8_lossy(line[keyword.len()..].trim_ascii()).into_owned();
            match keyword {
                b"v" => self.vertex(tokens, line_number)?,
                b"f" | b"fo" => self.face(tokens, line_number)?,
                b"o" | b"g" => {
                    let name = rest();
                    let name = if name.is_empty() { "default".to_string() } else { name };
                    // An object named again continues (exporters repeat `g default`).
                    self.object_index = intern(&mut self.object_names, &mut self.object_index_by_name, name);
                    self.chunk_index = None;
                }
                b"usemtl" => {
                    let name = rest();
                    let index = intern(&mut self.material_names, &mut self.material_index_by_name, name);
                    self.material_index = Some(index);
                    self.chunk_index = None;
                }
                b"mtllib" => self.libraries.push((rest(), line_number)),
                b"l" | b"p" => {
                    self.ignored_point_and_line_count += 1;
                    self.warnings
                        .add(self.path, POINT_OR_LINE, Location::Line(line_number), "");
                }
                _ => {}
            }
        }
        Ok(())
    }

    fn vertex<'a>(&mut self, mut tokens: impl Iterator<Item = &'a [u8]>, line: u64) -> Result<(), LoadError> {
        if self.positions.len() >= u32::MAX as usize {
            return Err(LoadError::Unsupported {
                path: self.path.to_path_buf(),
                location: Location::Line(line),
                message: "more than 2^32 - 1 vertices".into(),
            });
        }
        let mut xyz = [0.0f32; 3];
        for value in &mut xyz {
            let Some(token) = tokens.next() else {
                return Err(self.parse_error(line, "a vertex needs three coordinates".into()));
            };
            let parsed = std::str::from_utf8(token).ok().and_then(|s| s.parse::<f32>().ok());
            let Some(parsed) = parsed else {
                return Err(self.parse_error(
                    line,
                    format!("bad vertex coordinate '{}'", String::from_utf8_lossy(token)),
                ));
            };
            if !parsed.is_finite() {
                return Err(LoadError::NonFinite {
                    path: self.path.to_path_buf(),
                    location: Location::Line(line),
                    value: parsed,
                });
            }
            *value = parsed;
        }
        self.positions.push(Vec3::from_array(xyz));
        Ok(())
    }

    fn face<'a>(&mut self, tokens: impl Iterator<Item = &'a [u8]>, line: u64) -> Result<(), LoadError> {
        self.corners.clear();
        for token in tokens {
            let vertex_part = token.split(|&b| b == b'/').next().unwrap_or(token);
            let Some(written) = parse_i64(vertex_part) else {
                return Err(self.parse_error(line, format!("bad face corner '{}'", String::from_utf8_lossy(token))));
            };
            let index = self.resolve(written, line)?;
            self.corners.push(index);
        }
        // The format has `p` and `l` for points and lines, but some exporters write faces of
        // one or two corners; other readers skip them, so they are counted and skipped here
        // (their corners were still checked above).
        if self.corners.len() < 3 {
            self.short_face_count += 1;
            self.warnings.add(self.path, SHORT_FACE, Location::Line(line), "");
            return Ok(());
        }
        let chunk_index = self.current_chunk();
        fan_triangulate(&self.corners, &mut self.chunks[chunk_index].triangles);
        Ok(())
    }

    /// The 0-based vertex of a 1-based or negative (relative) reference.
    fn resolve(&mut self, written: i64, line: u64) -> Result<u32, LoadError> {
        let defined = self.positions.len() as i64;
        let index = match written {
            w if w > 0 => w - 1,
            w if w < 0 => defined + w,
            _ => -1,
        };
        if index < 0 || index >= i64::from(u32::MAX) {
            return Err(LoadError::IndexOutOfRange {
                path: self.path.to_path_buf(),
                location: Location::Line(line),
                index: written,
                vertex_count: defined as u64,
            });
        }
        // In range of u32 by the test above.
        let index = index as u32;
        if index as usize >= self.positions.len() && self.forward.is_none_or(|f| index > f.index) {
            self.forward = Some(ForwardReference { index, written, line });
        }
        Ok(index)
    }

    fn current_chunk(&mut self) -> usize {
        if let Some(index) = self.chunk_index {
            return index;
        }
        let key = (self.object_index, self.material_index);
        let next_index = self.chunks.len();
        let index = *self.chunk_by_key.entry(key).or_insert(next_index);
        if index == next_index {
            self.chunks.push(Chunk {
                object_index: key.0,
                material_index: key.1,
                triangles: Vec::new(),
            });
        }
        self.chunk_index = Some(index);
        index
    }

    fn finish(mut self, files: &dyn ExternalFiles) -> Result<LoadedScene, LoadError> {
        let path = self.path;
        if let Some(forward) = self.forward {
            if forward.index as usize >= self.positions.len() {
                return Err(LoadError::IndexOutOfRange {
                    path: path.to_path_buf(),
                    location: Location::Line(forward.line),
                    index: forward.written,
                    vertex_count: self.positions.len() as u64,
                });
            }
        }
        if self.chunks.iter().all(|c| c.triangles.is_empty()) {
            let reason = if self.ignored_point_and_line_count > 0 {
                "the file has only points and lines"
            } else if self.short_face_count > 0 {
                "the file has only faces with fewer than 3 corners"
            } else {
                "the file has no faces"
            };
            return Err(LoadError::Empty {
                path: path.to_path_buf(),
                reason: reason.into(),
            });
        }

        let mut warnings = std::mem::take(&mut self.warnings);
        let colors = self.material_colors(files, &mut warnings);

        let mut chunks_per_object = vec![0usize; self.object_names.len()];
        for chunk in &self.chunks {
            chunks_per_object[chunk.object_index] += 1;
        }
        let mut remap = vec![u32::MAX; self.positions.len()];
        let mut meshes = Vec::with_capacity(self.chunks.len());
        for chunk in &self.chunks {
            let object = &self.object_names[chunk.object_index];
            let name = match chunk.material_index {
                Some(m) if chunks_per_object[chunk.object_index] > 1 => {
                    format!("{object} [{}]", self.material_names[m])
                }
                _ => object.clone(),
            };
            let core_error = |source| LoadError::Core {
                path: path.to_path_buf(),
                part: format!("object '{name}'"),
                source,
            };
            let mut mesh = compact_mesh(&self.positions, &chunk.triangles, &mut remap).map_err(core_error)?;
            if let Some(color) = chunk.material_index.and_then(|m| colors[m]) {
                mesh = mesh.with_colors(MeshColors::PerMesh(color)).map_err(core_error)?;
            }
            meshes.push((name, mesh));
        }
        let scene = scene_of_meshes(path, &file_stem(path), meshes)?;
        Ok(LoadedScene {
            scene,
            warnings: warnings.into_lines(),
        })
    }

    /// The diffuse color of each material named by `usemtl`, from the libraries named by
    /// `mtllib`; what cannot be found becomes a warning. A library named several times is read
    /// once (the cost stays linear in the files' sizes).
    fn material_colors(&self, files: &dyn ExternalFiles, warnings: &mut Warnings) -> Vec<Option<Rgba8>> {
        let folder = self.path.parent().unwrap_or(Path::new(""));
        let mut library = HashMap::new();
        let mut all_libraries_read = true;
        let mut libraries_seen: HashSet<PathBuf> = HashSet::new();
        for (names, line) in &self.libraries {
            for mtl_path in library_paths(files, folder, names) {
                if !libraries_seen.insert(mtl_path.clone()) {
                    continue;
                }
                match files.read(&mtl_path) {
                    Ok(data) => parse_mtl(files, &mtl_path, &data, &mut library, warnings),
                    Err(error) => {
                        all_libraries_read = false;
                        warnings.add(
                            self.path,
                            LIBRARY_NOT_READ,
                            Location::Line(*line),
                            format!("{}: {error}", mtl_path.display()),
                        );
                    }
                }
            }
        }
        let colors: Vec<Option<Rgba8>> = self
            .material_names
            .iter()
            .map(|name| library.get(name).copied().flatten())
            .collect();
        let undefined: Vec<&str> = self
            .material_names
            .iter()
            .filter(|name| !library.contains_key(*name))
            .map(String::as_str)
            .collect();
        if all_libraries_read && !undefined.is_empty() {
            warnings.add(self.path, UNDEFINED_MATERIALS, Location::File, list_names(&undefined));
        }
        colors
    }
}

/// The index of `name` in `names`, added at the end if new.
fn intern(names: &mut Vec<String>, index_by_name: &mut HashMap<String, usize>, name: String) -> usize {
    let next_index = names.len();
    let index = *index_by_name.entry(name.clone()).or_insert(next_index);
    if index == next_index {
        names.push(name);
    }
    index
}

/// The library files of a `mtllib` statement: the whole rest of the line when that file exists
/// (names with spaces), otherwise each whitespace-separated name.
fn library_paths(files: &dyn ExternalFiles, folder: &Path, names: &str) -> Vec<PathBuf> {
    let whole = folder.join(names.replace('\\', "/"));
    if files.is_file(&whole) || !names.contains(char::is_whitespace) {
        return vec![whole];
    }
    names
        .split_whitespace()
        .map(|name| folder.join(name.replace('\\', "/")))
        .collect()
}

/// Reads the diffuse colors of an `.mtl` file into `library` and warns about texture files that
/// do not exist (textures are never loaded; the warning says the model will look different).
fn parse_mtl(
    files: &dyn ExternalFiles,
    mtl_path: &Path,
    data: &[u8],
    library: &mut HashMap<String, Option<Rgba8>>,
    warnings: &mut Warnings,
) {
    let folder = mtl_path.parent().unwrap_or(Path::new(""));
    let mut current: Option<String> = None;
    // In order of first mention; the set keeps the test linear in the number of statements.
    let mut missing_textures: Vec<String> = Vec::new();
    let mut textures_seen: HashSet<String> = HashSet::new();
    for (line_index, line) in statement_lines(data) {
        let mut tokens = tokens_of(line);
        let Some(keyword) = tokens.next() else { continue };
        match keyword {
            b"newmtl" => {
                let name = String::from_utf8_lossy(line[keyword.len()..].trim_ascii()).into_owned();
                library.insert(name.clone(), None);
                current = Some(name);
            }
            b"Kd" => {
                let values: Vec<Option<f32>> = tokens
                    .map(|t| std::str::from_utf8(t).ok().and_then(|s| s.parse::<f32>().ok()))
                    .collect();
                // `Kd r` alone means gray (MTL spec); `Kd spectral ...` and `Kd xyz ...` are not read.
                let rgb = match values.as_slice() {
                    [Some(v)] => Some([*v; 3]),
                    [Some(r), Some(g), Some(b), ..] => Some([*r, *g, *b]),
                    _ => None,
                };
                match (rgb, &current) {
                    (Some(rgb), Some(name)) => {
                        library.insert(
                            name.clone(),
                            Some([unit_to_u8(rgb[0]), unit_to_u8(rgb[1]), unit_to_u8(rgb[2]), 255]),
                        );
                    }
                    (None, _) => warnings.add(
                        mtl_path,
                        DIFFUSE_NOT_READ,
                        Location::Line(line_index as u64 + 1),
                        quoted(&String::from_utf8_lossy(line)),
                    ),
                    (Some(_), None) => {}
                }
            }
            _ if is_texture_statement(keyword) => {
                // Options (`-s 1 1 1`, `-bm 0.5`) come first; the file name is last.
                if let Some(name) = tokens.next_back() {
                    let name = String::from_utf8_lossy(name).replace('\\', "/");
                    if textures_seen.insert(name.clone()) && !files.is_file(&folder.join(&name)) {
                        missing_textures.push(name);
                    }
                }
            }
            _ => {}
        }
    }
    if !missing_textures.is_empty() {
        let names: Vec<&str> = missing_textures.iter().map(String::as_str).collect();
        warnings.add_count(
            mtl_path,
            MISSING_TEXTURES,
            missing_textures.len() as u64,
            Location::File,
            list_names(&names),
        );
    }
}

/// The lines of an OBJ or MTL file with their 0-based indices, each cut at its `#` comment and
/// trimmed of ASCII white space (an empty slice for a blank or comment-only line).
fn statement_lines(data: &[u8]) -> impl Iterator<Item = (usize, &[u8])> {
    data.split(|&b| b == b'\n').enumerate().map(|(line_index, raw_line)| {
        let line = match raw_line.iter().position(|&b| b == b'#') {
            Some(comment_start) => &raw_line[..comment_start],
            None => raw_line,
        };
        (line_index, line.trim_ascii())
    })
}

/// The white-space separated tokens of a statement line: the keyword first.
fn tokens_of(line: &[u8]) -> impl DoubleEndedIterator<Item = &[u8]> {
    line.split(|b| b.is_ascii_whitespace()).filter(|t| !t.is_empty())
}

fn is_texture_statement(keyword: &[u8]) -> bool {
    keyword.starts_with(b"map_") || matches!(keyword, b"bump" | b"disp" | b"decal" | b"refl" | b"norm")
}

/// `a, b, c, d, e and 7 more`.
fn list_names(names: &[&str]) -> String {
    let mut text = names
        .iter()
        .take(LISTED_NAMES_MAX)
        .copied()
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > LISTED_NAMES_MAX {
        text.push_str(&format!(" and {} more", names.len() - LISTED_NAMES_MAX));
    }
    text
}

/// A decimal integer with an optional sign; `None` when malformed or out of `i64`.
fn parse_i64(token: &[u8]) -> Option<i64> {
    let (negative, digits) = match token.split_first()? {
        (b'-', rest) => (true, rest),
        (b'+', rest) => (false, rest),
        _ => (false, token),
    };
    if digits.is_empty() {
        return None;
    }
    let mut value: i64 = 0;
    for &d in digits {
        if !d.is_ascii_digit() {
            return None;
        }
        value = value.checked_mul(10)?.checked_add(i64::from(d - b'0'))?;
    }
    Some(if negative { -value } else { value })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_i64_accepts_signs_and_rejects_junk() {
        assert_eq!(parse_i64(b"42"), Some(42));
        assert_eq!(parse_i64(b"-3"), Some(-3));
        assert_eq!(parse_i64(b"+7"), Some(7));
        assert_eq!(parse_i64(b""), None);
        assert_eq!(parse_i64(b"-"), None);
        assert_eq!(parse_i64(b"1x"), None);
        assert_eq!(parse_i64(b"99999999999999999999999"), None);
    }

    #[test]
    fn relative_and_forward_references() {
        let path = Path::new("t.obj");
        let mut reader = ObjReader::new(path);
        reader
            .parse(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nf 1 2 4\nv 1 1 0\n")
            .expect("forward references are checked at finish, not while parsing");
        assert_eq!(reader.chunks[0].triangles, vec![[0, 1, 2], [0, 1, 3]]);
        let loaded = reader.finish(&Disk).expect("the relative indices resolve");
        assert_eq!(loaded.scene.item_count(), 2);
    }

    #[test]
    fn forward_reference_past_the_end_names_its_line() {
        let mut reader = ObjReader::new(Path::new("t.obj"));
        reader
            .parse(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n")
            .expect("forward references are checked at finish, not while parsing");
        let error = reader.finish(&Disk).unwrap_err().to_string();
        assert_eq!(error, "t.obj line 5: vertex index 9 is out of range (vertex count 3)");
    }

    #[test]
    fn zero_and_too_negative_references_are_errors() {
        // Also in faces too short to be drawn: the index is wrong all the same.
        for face in ["f 0 1 2", "f -4 1 2", "f 0 1", "f 1 -4"] {
            let mut reader = ObjReader::new(Path::new("t.obj"));
            let text = format!("v 0 0 0\nv 1 0 0\nv 0 1 0\n{face}\n");
            assert!(
                matches!(reader.parse(text.as_bytes()), Err(LoadError::IndexOutOfRange { .. })),
                "{face}"
            );
        }
    }

    #[test]
    fn names_are_listed_with_a_tail() {
        assert_eq!(list_names(&["a", "b"]), "a, b");
        assert_eq!(
            list_names(&["a", "b", "c", "d", "e", "f", "g"]),
            "a, b, c, d, e and 2 more"
        );
    }
}
