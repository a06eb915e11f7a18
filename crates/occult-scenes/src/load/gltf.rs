//! glTF 2.0: JSON (`.gltf`, buffers in `.bin` files or base64 data URIs) and binary (`.glb`).
//!
//! # References
//! - Khronos Group, *glTF 2.0 Specification*: §3.5 scenes, nodes and hierarchy (a node's local
//!   matrix or TRS places its mesh and children in its parent's space), §3.6 binary data storage
//!   (buffers, buffer views, byte strides, accessors, normalized and sparse accessors), §3.7.2
//!   meshes (primitives and their topology modes), §3.9 materials (`baseColorFactor`, linear),
//!   §4 the GLB container (header, JSON and BIN chunks).
//! - Khronos Group, *KHR_mesh_quantization* (glTF 2.0 extension): the component types allowed
//!   for `POSITION` (and other attributes) besides `FLOAT`.
//!
//! The node hierarchy is kept as instancing, so that memory stays O(unique geometry):
//! - each glTF **mesh** becomes one occult mesh node, all its triangle primitives merged
//!   (`TRIANGLES`, `TRIANGLE_STRIP`, `TRIANGLE_FAN`; points and lines are skipped with a
//!   warning), built once however many nodes use it;
//! - a glTF **node** with children becomes a group holding its mesh (identity instance) and its
//!   children (instances with their local transforms); a node with a mesh and no children is
//!   represented by the mesh node itself, placed by its parent;
//! - the scene's root nodes sit under one root group. The default scene is loaded (the first
//!   scene when none is marked; every parentless node when the file has no scene).
//!
//! The JSON is parsed and validated by the `gltf` crate (which checks every cross-reference).
//! Buffers and accessors are read here with overflow-checked offsets (see the module doc of
//! `load`): an accessor that reaches past its buffer view, a view past its buffer, a sparse
//! index out of range, an index past the primitive's vertices and a non-finite position are
//! errors naming the mesh, primitive and accessor. Skins, morph targets, cameras and lights are
//! ignored. A node with a singular transform (scale 0, used to hide objects) is skipped with a
//! warning; a projective node matrix loses its projective row.
//!
//! `KHR_mesh_quantization` (Khronos extension, ratified): positions may be `BYTE`,
//! `UNSIGNED_BYTE`, `SHORT` or `UNSIGNED_SHORT`, normalized or not, as well as `FLOAT`. They are
//! dequantized exactly as glTF §3.6.2 (`accessor.normalized`) says: a normalized `SHORT` `c` is
//! `max(c / 32767, -1)`, an `UNSIGNED_SHORT` `c / 65535`, likewise for bytes (127, 255); a plain
//! integer is its value. The node transforms that the quantizer wrote then place the mesh, as for
//! any mesh. The extension is accepted whether or not the file lists it, and whether or not it
//! requires it.
//!
//! `EXT_meshopt_compression` (gltfpack's `-c`): a compressed buffer view is decoded (module
//! `meshopt`) the first time an accessor reads it, and stands for the view's bytes from then on;
//! fallback buffers are never read. A file that requires another extension the `gltf` crate does
//! not enable (`KHR_draco_mesh_compression`: see `docs/loaders.md` for why it has no decoder
//! here) is refused by its validation ([`LoadError::Parse`]).
//!
//! Warnings (one line per kind, with a count and the first place): point and line primitives,
//! primitives without `POSITION`, triangle index counts not a multiple of 3, singular and
//! projective node transforms, and a file with several scenes.

use std::borrow::Cow;
use std::cell::OnceCell;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::buffer::Source;
use ::gltf::mesh::Mode;
use ::gltf::{Accessor, Document, Semantic};
use occult_core::{Affine3A, Instance, Mat4, MeshColors, NodeId, Rgba8, SceneBuilder, Vec3, Vec4};

use super::meshopt::{self, CompressedView};
use super::{compact_mesh, file_stem, linear_to_srgb_u8, read_bytes, unit_to_u8, LoadError, LoadedScene, Location};
use super::{Disk, ExternalFiles};
use super::{WarningKind, Warnings};

/// The bytes of one buffer: borrowed from the GLB's BIN chunk, or read (a file, a data URI);
/// shared by the buffers that name the same file.
type Buffer<'d> = Rc<Cow<'d, [u8]>>;

/// Deepest glTF node chain accepted; the scene model allows 64 levels in all (root group and
/// mesh included).
const MAX_NODE_DEPTH: usize = 60;

/// Required extensions read here although the `gltf` crate's validation refuses them.
/// `KHR_mesh_quantization` only widens the component types attributes may have; positions of
/// every integer type are read (and dequantized) by `component`. `EXT_meshopt_compression` views
/// are decoded by `GltfLoader::view_bytes`.
const EXTENSIONS_READ_HERE: [&str; 2] = ["KHR_mesh_quantization", meshopt::EXTENSION];

const SEVERAL_SCENES: WarningKind = WarningKind {
    one: "the file has several scenes; one is loaded",
    many: "the file has several scenes; one is loaded",
};
const PROJECTIVE_NODE: WarningKind = WarningKind {
    one: "projective transform; its last row is ignored",
    many: "nodes with a projective transform; their last rows are ignored",
};
const SINGULAR_NODE: WarningKind = WarningKind {
    one: "singular transform (a zero scale?); the node is skipped",
    many: "nodes with a singular transform (a zero scale?) skipped",
};
const POINT_OR_LINE_PRIMITIVE: WarningKind = WarningKind {
    one: "point or line primitive skipped",
    many: "point and line primitives skipped",
};
const NO_POSITION: WarningKind = WarningKind {
    one: "primitive without POSITION skipped",
    many: "primitives without POSITION skipped",
};
const INDEX_REMAINDER: WarningKind = WarningKind {
    one: "triangle indices not a multiple of 3; the last ones ignored",
    many: "primitives with triangle indices not a multiple of 3; the last ones ignored",
};

/// Loads a `.gltf` or `.glb` file (told apart by content: a GLB starts with `glTF`).
///
/// # Errors
/// [`LoadError::Io`]; [`LoadError::Parse`] for malformed or invalid JSON (with its line) and
/// malformed accessors; [`LoadError::Truncated`] for a GLB or JSON that ends early;
/// [`LoadError::Buffer`] for a missing, unreadable or too short buffer (naming its URI);
/// [`LoadError::CountMismatch`] for an accessor or view past the end of its data;
/// [`LoadError::AbsurdCount`] for an accessor larger than all the file's buffers;
/// [`LoadError::IndexOutOfRange`]; [`LoadError::NonFinite`]; [`LoadError::Unsupported`] for
/// position or index accessors of a type the format does not allow; [`LoadError::Empty`] when
/// the scene holds no triangle; [`LoadError::Core`] for a node hierarchy with a cycle or deeper
/// than the scene model allows.
pub fn load_gltf(path: &Path) -> Result<LoadedScene, LoadError> {
    gltf_from_bytes(path, &read_bytes(path)?, &Disk)
}

/// [`load_gltf`] of bytes in memory; `path` names them and locates external buffers, which
/// are read from `files`.
pub(super) fn gltf_from_bytes(path: &Path, data: &[u8], files: &dyn ExternalFiles) -> Result<LoadedScene, LoadError> {
    // JSON strings (URIs, names) may hold line breaks: the error stays one line.
    read_document(path, data, files).map_err(LoadError::one_line)
}

fn read_document(path: &Path, data: &[u8], files: &dyn ExternalFiles) -> Result<LoadedScene, LoadError> {
    check_glb_header(path, data)?;
    // A GLB's chunks are borrowed from `data`: the BIN chunk is read in place, not copied.
    let glb = if data.starts_with(b"glTF") {
        Some(::gltf::binary::Glb::from_slice(data).map_err(|e| document_error(path, e))?)
    } else {
        None
    };
    let json_bytes = glb.as_ref().map_or(data, |glb| &glb.json);
    let blob = glb.as_ref().and_then(|glb| glb.bin.as_deref());
    let mut json = ::gltf::json::deserialize::from_slice::<::gltf::json::Root>(json_bytes)
        .map_err(|e| document_error(path, ::gltf::Error::Deserialize(e)))?;
    json.extensions_required
        .retain(|name| !EXTENSIONS_READ_HERE.contains(&name.as_str()));
    check_position_references(path, &json)?;
    let document = Document::from_json(json).map_err(|e| document_error(path, e))?;
    let buffers = load_buffers(path, &document, blob, files)?;
    let mut loader = GltfLoader::new(path, &document, buffers);
    let root = loader.scene_root()?;
    let GltfLoader { builder, warnings, .. } = loader;
    let scene = builder.build(root).map_err(|source| LoadError::Core {
        path: path.to_path_buf(),
        part: "scene".into(),
        source,
    })?;
    Ok(LoadedScene {
        scene,
        warnings: warnings.into_lines(),
    })
}

/// Refuses a GLB whose header is short or declares more bytes than the file has (the `gltf`
/// crate subtracts the header size from the declared length unchecked).
fn check_glb_header(path: &Path, data: &[u8]) -> Result<(), LoadError> {
    if !data.starts_with(b"glTF") {
        return Ok(());
    }
    let truncated = |message: String| LoadError::Truncated {
        path: path.to_path_buf(),
        location: Location::File,
        message,
    };
    let Some(length) = data.get(8..12) else {
        return Err(truncated(format!(
            "the GLB header needs 12 bytes, the file has {}",
            data.len()
        )));
    };
    let declared = u32::from_le_bytes([length[0], length[1], length[2], length[3]]) as usize;
    if declared < 12 {
        return Err(LoadError::Parse {
            path: path.to_path_buf(),
            location: Location::File,
            message: format!("the GLB header declares a total length of {declared} bytes, less than the header"),
        });
    }
    if declared > data.len() {
        return Err(truncated(format!(
            "the GLB header declares {declared} bytes, the file has {}",
            data.len()
        )));
    }
    Ok(())
}

/// Refuses a primitive whose `POSITION` names a missing accessor. Deviation: the `gltf` crate's
/// validation indexes the accessor list with that index unchecked (a panic), so this runs first.
fn check_position_references(path: &Path, json: &::gltf::json::Root) -> Result<(), LoadError> {
    for (mesh_index, mesh) in json.meshes.iter().enumerate() {
        for (primitive_index, primitive) in mesh.primitives.iter().enumerate() {
            let position = primitive
                .attributes
                .get(&::gltf::json::validation::Checked::Valid(Semantic::Positions));
            if let Some(accessor) = position.filter(|a| a.value() >= json.accessors.len()) {
                return Err(LoadError::Parse {
                    path: path.to_path_buf(),
                    location: Location::Part(format!("mesh {mesh_index} primitive {primitive_index}")),
                    message: format!(
                        "POSITION names accessor {}, the file has {}",
                        accessor.value(),
                        json.accessors.len()
                    ),
                });
            }
        }
    }
    Ok(())
}

fn document_error(path: &Path, error: ::gltf::Error) -> LoadError {
    use ::gltf::binary::Error as GlbError;
    let path = path.to_path_buf();
    match error {
        ::gltf::Error::Deserialize(json) => {
            let location = Location::Line(json.line() as u64);
            let message = format!("bad JSON: {json}");
            if json.is_eof() {
                LoadError::Truncated {
                    path,
                    location,
                    message,
                }
            } else {
                LoadError::Parse {
                    path,
                    location,
                    message,
                }
            }
        }
        ::gltf::Error::Validation(errors) => {
            let listed: Vec<String> = errors.iter().take(5).map(|(p, e)| format!("{p}: {e}")).collect();
            let more = if errors.len() > 5 {
                format!(" and {} more", errors.len() - 5)
            } else {
                String::new()
            };
            LoadError::Parse {
                path,
                location: Location::File,
                message: format!("invalid glTF document: {}{more}", listed.join("; ")),
            }
        }
        ::gltf::Error::Binary(GlbError::ChunkLength { .. } | GlbError::Length { .. }) => LoadError::Truncated {
            path,
            location: Location::File,
            message: error.to_string(),
        },
        ::gltf::Error::Binary(GlbError::Io(io)) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            LoadError::Truncated {
                path,
                location: Location::File,
                message: "a GLB chunk header is cut off".into(),
            }
        }
        other => LoadError::Parse {
            path,
            location: Location::File,
            message: other.to_string(),
        },
    }
}

/// The bytes of every buffer of the document, in order. Buffers naming the same file share
/// one read of it, so that memory stays bounded by the files' sizes however many buffers name
/// them.
fn load_buffers<'d>(
    path: &Path,
    document: &Document,
    mut blob: Option<&'d [u8]>,
    files: &dyn ExternalFiles,
) -> Result<Vec<Buffer<'d>>, LoadError> {
    let folder = path.parent().unwrap_or(Path::new(""));
    let mut buffers: Vec<Buffer<'d>> = Vec::new();
    let mut read_files: HashMap<PathBuf, Buffer<'d>> = HashMap::new();
    for buffer in document.buffers() {
        let buffer_error = |uri: &str, message: String| LoadError::Buffer {
            path: path.to_path_buf(),
            buffer_index: buffer.index(),
            uri: shorten_uri(uri),
            message,
        };
        if meshopt::is_fallback(buffer.extension_value(meshopt::EXTENSION)) {
            // Stands in for compressed views only, which name their data elsewhere; it may have
            // no data at all, and is never read (a view reading it is past its end).
            buffers.push(Rc::new(Cow::Borrowed(&[])));
            continue;
        }
        let (uri, data) = match buffer.source() {
            Source::Bin => {
                let uri = "<GLB BIN chunk>";
                (
                    uri,
                    Rc::new(Cow::Borrowed(
                        blob.take()
                            .ok_or_else(|| buffer_error(uri, "the file has no BIN chunk".into()))?,
                    )),
                )
            }
            Source::Uri(uri) if uri.starts_with("data:") => {
                // Base64 decoding by the `gltf` crate; no file access for data URIs.
                let data = ::gltf::buffer::Data::from_source(buffer.source(), None)
                    .map_err(|e| buffer_error(uri, format!("bad data URI: {e}")))?;
                (uri, Rc::new(Cow::Owned(data.0)))
            }
            Source::Uri(uri) => {
                let file = resolve_uri(folder, uri).map_err(|message| buffer_error(uri, message))?;
                if !files.is_file(&file) {
                    return Err(buffer_error(
                        uri,
                        format!("{} is not a file that can be read", file.display()),
                    ));
                }
                let data = match read_files.get(&file) {
                    Some(data) => Rc::clone(data),
                    None => {
                        let data = files
                            .read(&file)
                            .map_err(|e| buffer_error(uri, format!("cannot read {}: {e}", file.display())))?;
                        let data = Rc::new(Cow::Owned(data));
                        read_files.insert(file, Rc::clone(&data));
                        data
                    }
                };
                (uri, data)
            }
        };
        if data.len() < buffer.length() {
            return Err(buffer_error(
                uri,
                format!(
                    "has {} bytes, the document declares {} (truncated?)",
                    data.len(),
                    buffer.length()
                ),
            ));
        }
        buffers.push(data);
    }
    Ok(buffers)
}

/// The file a relative or `file:` URI names, percent-decoded, relative to `folder`.
fn resolve_uri(folder: &Path, uri: &str) -> Result<PathBuf, String> {
    let (relative, rest) = match uri.strip_prefix("file://").or_else(|| uri.strip_prefix("file:")) {
        Some(rest) => (false, rest),
        None if uri.contains(':') => return Err("unsupported URI scheme (only relative paths, file: and data:)".into()),
        None => (true, uri),
    };
    let decoded = percent_decode(rest).ok_or_else(|| "bad percent-encoding in URI".to_string())?;
    Ok(if relative {
        folder.join(decoded)
    } else {
        PathBuf::from(decoded)
    })
}

/// `%20` to a space, and so on; `None` when the result is not UTF-8.
fn percent_decode(text: &str) -> Option<String> {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| (b as char).to_digit(16);
        match (
            bytes[i],
            bytes.get(i + 1).copied().and_then(hex),
            bytes.get(i + 2).copied().and_then(hex),
        ) {
            (b'%', Some(high), Some(low)) => {
                out.push((high * 16 + low) as u8);
                i += 3;
            }
            (b, _, _) => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8(out).ok()
}

/// A URI as shown in messages: data URIs cut short.
fn shorten_uri(uri: &str) -> String {
    if uri.len() > 60 {
        let end = (0..=40).rev().find(|&i| uri.is_char_boundary(i)).unwrap_or(0);
        format!("{}...", &uri[..end])
    } else {
        uri.to_string()
    }
}

/// Where a glTF node stands in the depth-first build.
#[derive(Clone, Copy)]
enum Visit {
    Unvisited,
    InProgress,
    Done(Option<NodeId>),
}

/// Builds the scene of one document.
struct GltfLoader<'a> {
    path: &'a Path,
    document: &'a Document,
    buffers: Vec<Buffer<'a>>,
    /// Per buffer view: its `EXT_meshopt_compression` bytes once decoded.
    decoded_views: Vec<OnceCell<Vec<u8>>>,
    /// All buffer bytes and the declared sizes of the compressed views (a file named by several buffers counted once): no accessor may
    /// allocate more elements than this many bytes hold.
    buffer_bytes: usize,
    builder: SceneBuilder,
    /// Per glTF mesh: not built yet, or built (`None` when it has no triangle).
    meshes: Vec<Option<Option<NodeId>>>,
    visits: Vec<Visit>,
    warnings: Warnings,
}

impl<'a> GltfLoader<'a> {
    fn new(path: &'a Path, document: &'a Document, buffers: Vec<Buffer<'a>>) -> Self {
        let mut counted = std::collections::HashSet::new();
        let buffer_bytes = buffers
            .iter()
            .filter(|b| counted.insert(Rc::as_ptr(b)))
            .map(|b| b.len())
            .sum::<usize>()
            .saturating_add(
                document
                    .views()
                    .filter_map(|v| CompressedView::parse(v.extension_value(meshopt::EXTENSION)?).ok())
                    .map(|compressed| compressed.decoded_len())
                    .fold(0usize, usize::saturating_add),
            );
        Self {
            path,
            document,
            buffers,
            decoded_views: vec![OnceCell::new(); document.views().len()],
            buffer_bytes,
            builder: SceneBuilder::new(),
            meshes: vec![None; document.meshes().len()],
            visits: vec![Visit::Unvisited; document.nodes().len()],
            warnings: Warnings::default(),
        }
    }

    fn core_error(&self, part: String) -> impl FnOnce(occult_core::CoreError) -> LoadError + '_ {
        move |source| LoadError::Core {
            path: self.path.to_path_buf(),
            part,
            source,
        }
    }

    /// The root group of the scene to load.
    fn scene_root(&mut self) -> Result<NodeId, LoadError> {
        let document = self.document;
        let scene = document.default_scene().or_else(|| document.scenes().next());
        let scene_count = document.scenes().len();
        let (root_name, roots): (String, Vec<::gltf::Node<'a>>) = match &scene {
            Some(scene) => {
                if scene_count > 1 {
                    self.warnings.add(
                        self.path,
                        SEVERAL_SCENES,
                        Location::File,
                        format!("scene {} of {scene_count}", scene.index()),
                    );
                }
                (
                    scene.name().map_or_else(|| file_stem(self.path), str::to_string),
                    scene.nodes().collect(),
                )
            }
            None => {
                let mut is_child = vec![false; document.nodes().len()];
                for node in document.nodes() {
                    for child in node.children() {
                        is_child[child.index()] = true;
                    }
                }
                (
                    file_stem(self.path),
                    document.nodes().filter(|n| !is_child[n.index()]).collect(),
                )
            }
        };
        let mut instances = Vec::new();
        for node in roots {
            if let Some(child) = self.node(&node, 1)? {
                if let Some(parent_from_child) = self.node_transform(&node)? {
                    instances.push(Instance {
                        parent_from_child,
                        child,
                    });
                }
            }
        }
        if instances.is_empty() {
            return Err(LoadError::Empty {
                path: self.path.to_path_buf(),
                reason: "the scene has no node with a triangle mesh".into(),
            });
        }
        self.builder
            .add_group(root_name.as_str(), instances)
            .map_err(self.core_error(format!("scene '{root_name}'")))
    }

    /// The content of a node in its own space (before its transform): its mesh, or a group of its
    /// mesh and children; `None` when nothing below it has a triangle.
    fn node(&mut self, node: &::gltf::Node<'a>, depth: usize) -> Result<Option<NodeId>, LoadError> {
        let part = || match node.name() {
            Some(name) => format!("node {} '{name}'", node.index()),
            None => format!("node {}", node.index()),
        };
        match self.visits[node.index()] {
            Visit::Done(id) => return Ok(id),
            Visit::InProgress => {
                return Err(LoadError::Parse {
                    path: self.path.to_path_buf(),
                    location: Location::Part(part()),
                    message: "the node hierarchy has a cycle through this node".into(),
                })
            }
            Visit::Unvisited => {}
        }
        if depth > MAX_NODE_DEPTH {
            return Err(LoadError::Unsupported {
                path: self.path.to_path_buf(),
                location: Location::Part(part()),
                message: format!("node hierarchy deeper than {MAX_NODE_DEPTH} levels"),
            });
        }
        self.visits[node.index()] = Visit::InProgress;
        let mesh = match node.mesh() {
            Some(mesh) => self.mesh(&mesh)?,
            None => None,
        };
        let mut instances: Vec<Instance> = mesh
            .map(|child| Instance {
                parent_from_child: Affine3A::IDENTITY,
                child,
            })
            .into_iter()
            .collect();
        for child_node in node.children() {
            if let Some(child) = self.node(&child_node, depth + 1)? {
                if let Some(parent_from_child) = self.node_transform(&child_node)? {
                    instances.push(Instance {
                        parent_from_child,
                        child,
                    });
                }
            }
        }
        let id = match (mesh, node.children().len()) {
            (_, 0) => mesh,
            _ if instances.is_empty() => None,
            _ => Some(
                self.builder
                    .add_group(part(), instances)
                    .map_err(self.core_error(part()))?,
            ),
        };
        self.visits[node.index()] = Visit::Done(id);
        Ok(id)
    }

    /// A node's local transform; `None` (with a warning) when it is singular.
    fn node_transform(&mut self, node: &::gltf::Node<'_>) -> Result<Option<Affine3A>, LoadError> {
        let matrix = Mat4::from_cols_array_2d(&node.transform().matrix());
        let part = || Location::Part(format!("node {}", node.index()));
        if !matrix.is_finite() {
            return Err(LoadError::Parse {
                path: self.path.to_path_buf(),
                location: part(),
                message: "the transform is not finite".into(),
            });
        }
        if matrix.row(3) != Vec4::W {
            self.warnings.add(self.path, PROJECTIVE_NODE, part(), "");
        }
        let transform = Affine3A::from_mat4(matrix);
        if transform.matrix3.determinant() == 0.0 {
            self.warnings.add(self.path, SINGULAR_NODE, part(), "");
            return Ok(None);
        }
        Ok(Some(transform))
    }

    /// The occult mesh node of a glTF mesh (built on first use); `None` without triangles.
    fn mesh(&mut self, mesh: &::gltf::Mesh<'a>) -> Result<Option<NodeId>, LoadError> {
        if let Some(built) = self.meshes[mesh.index()] {
            return Ok(built);
        }
        let mesh_part = match mesh.name() {
            Some(name) => format!("mesh {} '{name}'", mesh.index()),
            None => format!("mesh {}", mesh.index()),
        };
        let mut positions: Vec<Vec3> = Vec::new();
        let mut triangles: Vec<[u32; 3]> = Vec::new();
        // Primitives often share one POSITION accessor: read it once.
        let mut first_vertex_of_accessor: HashMap<usize, u32> = HashMap::new();
        // (first triangle, color) per primitive with a material.
        let mut color_runs: Vec<(usize, Option<Rgba8>)> = Vec::new();
        for primitive in mesh.primitives() {
            let part = format!("{mesh_part} primitive {}", primitive.index());
            let mode = primitive.mode();
            if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
                self.warnings.add(
                    self.path,
                    POINT_OR_LINE_PRIMITIVE,
                    Location::Part(part),
                    format!("mode {mode:?}"),
                );
                continue;
            }
            let Some(position_accessor) = primitive.get(&Semantic::Positions) else {
                // The `gltf` validation requires POSITION; stay safe all the same.
                self.warnings.add(self.path, NO_POSITION, Location::Part(part), "");
                continue;
            };
            let vertex_count = position_accessor.count();
            let first_vertex = match first_vertex_of_accessor.get(&position_accessor.index()) {
                Some(&first) => first,
                None => {
                    let read = self.read_positions(&position_accessor, &part)?;
                    let first = u32::try_from(positions.len())
                        .ok()
                        .filter(|&f| u64::from(f) + read.len() as u64 <= u64::from(u32::MAX))
                        .ok_or_else(|| LoadError::Unsupported {
                            path: self.path.to_path_buf(),
                            location: Location::Part(part.clone()),
                            message: "more than 2^32 - 1 vertices in one mesh".into(),
                        })?;
                    if positions.is_empty() {
                        // The first accessor's vector becomes the mesh's: no copy.
                        positions = read;
                    } else {
                        positions.extend(read);
                    }
                    first_vertex_of_accessor.insert(position_accessor.index(), first);
                    first
                }
            };
            let first_triangle = triangles.len();
            if mode == Mode::Triangles {
                if let Some(accessor) = primitive.indices() {
                    let read = self.read_triangle_list(&accessor, &part, first_vertex, vertex_count, &mut triangles)?;
                    if let Some(index_count) = read {
                        if index_count % 3 != 0 {
                            self.warnings.add(
                                self.path,
                                INDEX_REMAINDER,
                                Location::Part(part.clone()),
                                format!("{index_count} indices"),
                            );
                        }
                        color_runs.push((first_triangle, primitive_color(&primitive)));
                        continue;
                    }
                }
            }
            let indices: Vec<u32> = match primitive.indices() {
                Some(accessor) => self.read_indices(&accessor, &part)?,
                // Fits: the positions were read, so `vertex_count` <= u32::MAX (checked above).
                None => (0..vertex_count as u32).collect(),
            };
            if let Some(&bad) = indices.iter().find(|&&i| i as usize >= vertex_count) {
                return Err(LoadError::IndexOutOfRange {
                    path: self.path.to_path_buf(),
                    location: Location::Part(part),
                    index: i64::from(bad),
                    vertex_count: vertex_count as u64,
                });
            }
            let global = |i: u32| first_vertex + i;
            match mode {
                Mode::Triangles => {
                    let chunks = indices.chunks_exact(3);
                    if !chunks.remainder().is_empty() {
                        self.warnings.add(
                            self.path,
                            INDEX_REMAINDER,
                            Location::Part(part.clone()),
                            format!("{} indices", indices.len()),
                        );
                    }
                    triangles.extend(chunks.map(|t| [global(t[0]), global(t[1]), global(t[2])]));
                }
                Mode::TriangleStrip => {
                    triangles.extend(indices.windows(3).enumerate().map(|(k, w)| {
                        // §3.7.2: odd strip triangles swap their first two corners to keep the winding.
                        if k % 2 == 0 {
                            [global(w[0]), global(w[1]), global(w[2])]
                        } else {
                            [global(w[1]), global(w[0]), global(w[2])]
                        }
                    }));
                }
                _ => {
                    if let Some((&hub, rest)) = indices.split_first() {
                        triangles.extend(rest.windows(2).map(|w| [global(hub), global(w[0]), global(w[1])]));
                    }
                }
            }
            color_runs.push((first_triangle, primitive_color(&primitive)));
        }

        let id = if triangles.is_empty() {
            None
        } else {
            let triangle_count = triangles.len();
            let mut built = if uses_every_vertex(&triangles, positions.len()) {
                // Nothing to drop (the common case: exporters write the vertices a primitive
                // uses): the arrays become the mesh as they are, without the compaction's copies.
                occult_core::Mesh::new(positions, triangles)
            } else {
                let mut remap = vec![u32::MAX; positions.len()];
                compact_mesh(&positions, &triangles, &mut remap)
            }
            .map_err(self.core_error(mesh_part.clone()))?;
            if let Some(colors) = mesh_colors(&color_runs, triangle_count) {
                built = built.with_colors(colors).map_err(self.core_error(mesh_part.clone()))?;
            }
            Some(
                self.builder
                    .add_mesh(mesh_part.as_str(), built)
                    .map_err(self.core_error(mesh_part.clone()))?,
            )
        };
        self.meshes[mesh.index()] = Some(id);
        Ok(id)
    }

    fn read_positions(&self, accessor: &Accessor<'_>, part: &str) -> Result<Vec<Vec3>, LoadError> {
        let location = || Location::Part(format!("{part}, POSITION accessor {}", accessor.index()));
        if accessor.dimensions() != Dimensions::Vec3 || accessor.data_type() == DataType::U32 {
            return Err(LoadError::Unsupported {
                path: self.path.to_path_buf(),
                location: location(),
                message: format!(
                    "positions of type {:?} {:?}",
                    accessor.dimensions(),
                    accessor.data_type()
                ),
            });
        }
        let data_type = accessor.data_type();
        let normalized = accessor.normalized();
        let size = component_size(data_type);
        let positions = if data_type == DataType::F32 {
            // The common case without a `match` per component.
            self.read_accessor(accessor, 12, Vec3::ZERO, &location, |bytes| {
                let x = bytes.first_chunk::<4>();
                let y = bytes.get(4..).and_then(<[u8]>::first_chunk::<4>);
                match (x, y, bytes.last_chunk::<4>()) {
                    (Some(&x), Some(&y), Some(&z)) => {
                        Vec3::new(f32::from_le_bytes(x), f32::from_le_bytes(y), f32::from_le_bytes(z))
                    }
                    // `read_accessor` passes 12 bytes.
                    _ => Vec3::NAN,
                }
            })?
        } else {
            self.read_accessor(accessor, 3 * size, Vec3::ZERO, &location, |bytes| {
                Vec3::new(
                    component(data_type, normalized, &bytes[..size]),
                    component(data_type, normalized, &bytes[size..2 * size]),
                    component(data_type, normalized, &bytes[2 * size..]),
                )
            })?
        };
        if let Some((vertex_index, p)) = positions.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            let value = p.to_array().into_iter().find(|v| !v.is_finite()).unwrap_or(f32::NAN);
            return Err(LoadError::NonFinite {
                path: self.path.to_path_buf(),
                location: Location::Part(format!(
                    "{part}, POSITION accessor {}, vertex {vertex_index}",
                    accessor.index()
                )),
                value,
            });
        }
        Ok(positions)
    }

    fn read_indices(&self, accessor: &Accessor<'_>, part: &str) -> Result<Vec<u32>, LoadError> {
        let location = || Location::Part(format!("{part}, index accessor {}", accessor.index()));
        let data_type = accessor.data_type();
        if accessor.dimensions() != Dimensions::Scalar
            || !matches!(data_type, DataType::U8 | DataType::U16 | DataType::U32)
        {
            return Err(LoadError::Unsupported {
                path: self.path.to_path_buf(),
                location: location(),
                message: format!("indices of type {:?} {:?}", accessor.dimensions(), data_type),
            });
        }
        let size = component_size(data_type);
        self.read_accessor(accessor, size, 0u32, &location, read_uint)
    }

    /// A `TRIANGLES` primitive's index accessor read straight into `triangles` (offset by
    /// `first_vertex`, each index checked against `vertex_count`), without an index list
    /// between: the number of indices, or `None` (nothing read) for what the general path
    /// reads (sparse indices, no buffer view, a byte stride).
    fn read_triangle_list(
        &self,
        accessor: &Accessor<'_>,
        part: &str,
        first_vertex: u32,
        vertex_count: usize,
        triangles: &mut Vec<[u32; 3]>,
    ) -> Result<Option<usize>, LoadError> {
        let location = || Location::Part(format!("{part}, index accessor {}", accessor.index()));
        let data_type = accessor.data_type();
        let size = component_size(data_type);
        let Some(view) = accessor.view() else {
            return Ok(None);
        };
        let count = accessor.count();
        // What the general path refuses, it refuses with its own errors.
        if accessor.sparse().is_some()
            || view.stride().is_some_and(|stride| stride != size)
            || accessor.dimensions() != Dimensions::Scalar
            || !matches!(data_type, DataType::U8 | DataType::U16 | DataType::U32)
            || count as u128 * size as u128 > self.buffer_bytes as u128
        {
            return Ok(None);
        }
        let bytes = self.view_bytes(&view, &location)?;
        let what = || format!("accessor {}", accessor.index());
        // Checks that the `count` indices fit the view; they are then contiguous.
        let _ = self.strided(bytes, accessor.offset(), count, size, size, &what, &location)?;
        let Some(bytes) = bytes.get(accessor.offset()..accessor.offset() + count * size) else {
            return Ok(None);
        };
        // Bounded by the view's bytes, just checked.
        triangles.reserve(count / 3);
        let pushed = match data_type {
            DataType::U32 => push_triangles(bytes, u32::from_le_bytes, first_vertex, vertex_count, triangles),
            DataType::U16 => push_triangles(
                bytes,
                |b| u32::from(u16::from_le_bytes(b)),
                first_vertex,
                vertex_count,
                triangles,
            ),
            _ => push_triangles(
                bytes,
                |[b]: [u8; 1]| u32::from(b),
                first_vertex,
                vertex_count,
                triangles,
            ),
        };
        match pushed {
            Ok(()) => Ok(Some(count)),
            Err(bad) => Err(LoadError::IndexOutOfRange {
                path: self.path.to_path_buf(),
                location: Location::Part(part.to_string()),
                index: i64::from(bad),
                vertex_count: vertex_count as u64,
            }),
        }
    }

    /// The elements of an accessor, each decoded from its `element_size` bytes; sparse
    /// substitution applied. Every offset is checked before it is used.
    fn read_accessor<T: Copy>(
        &self,
        accessor: &Accessor<'_>,
        element_size: usize,
        zero: T,
        location: &impl Fn() -> Location,
        decode: impl Fn(&[u8]) -> T,
    ) -> Result<Vec<T>, LoadError> {
        let count = accessor.count();
        let what = || format!("accessor {}", accessor.index());
        // No accessor may hold more elements than all buffers have bytes for (without a view, its
        // elements are zeros that cost memory all the same).
        if count as u128 * element_size as u128 > self.buffer_bytes as u128 {
            return Err(LoadError::AbsurdCount {
                path: self.path.to_path_buf(),
                what: what(),
                count: count as u64,
                min_bytes: element_size as u64,
                available_bytes: self.buffer_bytes as u64,
            });
        }
        let mut values = match accessor.view() {
            Some(view) => {
                let stride = view.stride().unwrap_or(element_size);
                let bytes = self.view_bytes(&view, location)?;
                let elements = self.strided(bytes, accessor.offset(), count, element_size, stride, &what, location)?;
                elements.map(&decode).collect()
            }
            None => vec![zero; count],
        };
        if let Some(sparse) = accessor.sparse() {
            let sparse_count = sparse.count();
            let indices = sparse.indices();
            let index_size = match indices.index_type() {
                ::gltf::accessor::sparse::IndexType::U8 => 1,
                ::gltf::accessor::sparse::IndexType::U16 => 2,
                ::gltf::accessor::sparse::IndexType::U32 => 4,
            };
            let index_bytes = self.view_bytes(&indices.view(), location)?;
            let index_elements = self.strided(
                index_bytes,
                indices.offset(),
                sparse_count,
                index_size,
                index_size,
                &what,
                location,
            )?;
            let value_bytes = self.view_bytes(&sparse.values().view(), location)?;
            let value_elements = self.strided(
                value_bytes,
                sparse.values().offset(),
                sparse_count,
                element_size,
                element_size,
                &what,
                location,
            )?;
            for (index_bytes, value_bytes) in index_elements.zip(value_elements) {
                let index = read_uint(index_bytes) as usize;
                let Some(slot) = values.get_mut(index) else {
                    return Err(LoadError::Parse {
                        path: self.path.to_path_buf(),
                        location: location(),
                        message: format!("sparse index {index} past the accessor's {count} elements"),
                    });
                };
                *slot = decode(value_bytes);
            }
        }
        Ok(values)
    }

    /// The bytes of a buffer view, checked against its buffer; a compressed view's decoded
    /// bytes (decoded on first use).
    fn view_bytes(
        &self,
        view: &::gltf::buffer::View<'_>,
        location: &impl Fn() -> Location,
    ) -> Result<&[u8], LoadError> {
        if let Some(object) = view.extension_value(meshopt::EXTENSION) {
            let cell = &self.decoded_views[view.index()];
            if let Some(decoded) = cell.get() {
                return Ok(decoded);
            }
            let bad = |message: String| LoadError::Parse {
                path: self.path.to_path_buf(),
                location: location(),
                message: format!("buffer view {}: {message}", view.index()),
            };
            let compressed = CompressedView::parse(object).map_err(bad)?;
            let source = self
                .buffers
                .get(compressed.buffer_index)
                .and_then(|buffer| {
                    let end = compressed.byte_offset.checked_add(compressed.byte_length)?;
                    buffer.get(compressed.byte_offset..end)
                })
                .ok_or_else(|| LoadError::CountMismatch {
                    path: self.path.to_path_buf(),
                    location: location(),
                    message: format!(
                        "buffer view {}: {} bytes {}..+{} reach past the end of buffer {} (or there is no such buffer)",
                        view.index(),
                        meshopt::EXTENSION,
                        compressed.byte_offset,
                        compressed.byte_length,
                        compressed.buffer_index
                    ),
                })?;
            let decoded = compressed.decode(source).map_err(bad)?;
            return Ok(cell.get_or_init(|| decoded));
        }
        let buffer = &self.buffers[view.buffer().index()];
        view.offset()
            .checked_add(view.length())
            .and_then(|end| buffer.get(view.offset()..end))
            .ok_or_else(|| LoadError::CountMismatch {
                path: self.path.to_path_buf(),
                location: location(),
                message: format!(
                    "buffer view {} (bytes {}..+{}) reaches past the end of buffer {} ({} bytes)",
                    view.index(),
                    view.offset(),
                    view.length(),
                    view.buffer().index(),
                    buffer.len()
                ),
            })
    }

    /// `count` elements of `element_size` bytes, `stride` apart from `offset` in `bytes`.
    #[allow(clippy::too_many_arguments)]
    fn strided<'b>(
        &self,
        bytes: &'b [u8],
        offset: usize,
        count: usize,
        element_size: usize,
        stride: usize,
        what: &impl Fn() -> String,
        location: &impl Fn() -> Location,
    ) -> Result<impl Iterator<Item = &'b [u8]> + 'b, LoadError> {
        if stride < element_size {
            return Err(LoadError::Parse {
                path: self.path.to_path_buf(),
                location: location(),
                message: format!(
                    "{}: byte stride {stride} is smaller than its elements ({element_size} bytes)",
                    what()
                ),
            });
        }
        let end = match count {
            0 => Some(offset),
            _ => (count - 1)
                .checked_mul(stride)
                .and_then(|e| e.checked_add(offset))
                .and_then(|e| e.checked_add(element_size)),
        };
        if end.is_none_or(|end| end > bytes.len()) {
            return Err(LoadError::CountMismatch {
                path: self.path.to_path_buf(),
                location: location(),
                message: format!(
                    "{}: {count} elements of {element_size} bytes, {stride} apart from byte {offset}, \
                     do not fit in its buffer view of {} bytes",
                    what(),
                    bytes.len()
                ),
            });
        }
        // In bounds: the last element ends at `end` <= bytes.len(), checked above.
        Ok((0..count).map(move |i| &bytes[offset + i * stride..offset + i * stride + element_size]))
    }
}

/// Whether `triangles` name every vertex of `0..vertex_count` (indices already checked to be in
/// range). One pass over the indices, one byte per vertex.
fn uses_every_vertex(triangles: &[[u32; 3]], vertex_count: usize) -> bool {
    if triangles.len().saturating_mul(3) < vertex_count {
        return false;
    }
    let mut used = vec![false; vertex_count];
    for &i in triangles.iter().flatten() {
        used[i as usize] = true;
    }
    used.iter().all(|&u| u)
}

/// The sRGB base color of a primitive's material; `None` without a material.
fn primitive_color(primitive: &::gltf::Primitive<'_>) -> Option<Rgba8> {
    primitive.material().index().map(|_| {
        let [r, g, b, a] = primitive.material().pbr_metallic_roughness().base_color_factor();
        [
            linear_to_srgb_u8(r),
            linear_to_srgb_u8(g),
            linear_to_srgb_u8(b),
            unit_to_u8(a),
        ]
    })
}

/// Index triples of `N`-byte little-endian indices straight into `triangles`, offset by
/// `first_vertex`; a trailing partial triple is checked and left out. The first index not
/// below `vertex_count` is the error.
fn push_triangles<const N: usize>(
    bytes: &[u8],
    decode: impl Fn([u8; N]) -> u32,
    first_vertex: u32,
    vertex_count: usize,
    triangles: &mut Vec<[u32; 3]>,
) -> Result<(), u32> {
    let triples = bytes.chunks_exact(3 * N);
    let rest = triples.remainder();
    for t in triples {
        let a = t.first_chunk::<N>();
        let b = t.get(N..).and_then(<[u8]>::first_chunk::<N>);
        let (Some(&a), Some(&b), Some(&c)) = (a, b, t.last_chunk::<N>()) else {
            // `chunks_exact` gives 3 N bytes.
            continue;
        };
        let t = [decode(a), decode(b), decode(c)];
        if let Some(&bad) = t.iter().find(|&&i| i as usize >= vertex_count) {
            return Err(bad);
        }
        // No overflow: `first_vertex + vertex_count` <= u32::MAX was checked with the positions.
        triangles.push(t.map(|i| first_vertex + i));
    }
    let rest = rest.chunks_exact(N).filter_map(<[u8]>::first_chunk::<N>);
    match rest.map(|&b| decode(b)).find(|&i| i as usize >= vertex_count) {
        Some(bad) => Err(bad),
        None => Ok(()),
    }
}

/// Per-mesh colors from the primitives' materials: `None` when no primitive has a material,
/// one color when all agree, per triangle otherwise (primitives without one get white, the
/// glTF default material's base color).
fn mesh_colors(runs: &[(usize, Option<Rgba8>)], triangle_count: usize) -> Option<MeshColors> {
    if runs.iter().all(|(_, c)| c.is_none()) {
        return None;
    }
    let white = [255, 255, 255, 255];
    let first = runs[0].1.unwrap_or(white);
    if runs.iter().all(|(_, c)| c.unwrap_or(white) == first) {
        return Some(MeshColors::PerMesh(first));
    }
    let mut colors = Vec::with_capacity(triangle_count);
    for (k, (start, color)) in runs.iter().enumerate() {
        let end = runs.get(k + 1).map_or(triangle_count, |next| next.0);
        colors.extend(std::iter::repeat_n(color.unwrap_or(white), end - start));
    }
    Some(MeshColors::PerTriangle(colors))
}

fn component_size(data_type: DataType) -> usize {
    match data_type {
        DataType::I8 | DataType::U8 => 1,
        DataType::I16 | DataType::U16 => 2,
        DataType::U32 | DataType::F32 => 4,
    }
}

/// A little-endian unsigned integer of 1, 2 or 4 bytes.
fn read_uint(bytes: &[u8]) -> u32 {
    match *bytes {
        [b] => u32::from(b),
        [b0, b1] => u32::from(u16::from_le_bytes([b0, b1])),
        [b0, b1, b2, b3] => u32::from_le_bytes([b0, b1, b2, b3]),
        // Callers pass 1, 2 or 4 bytes (`component_size`).
        _ => unreachable!("integer of {} bytes", bytes.len()),
    }
}

/// One vector component as `f32`, with the normalization of §3.6.2 (the integer types are those
/// of `KHR_mesh_quantization`).
fn component(data_type: DataType, normalized: bool, bytes: &[u8]) -> f32 {
    match data_type {
        DataType::F32 => f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]),
        DataType::I8 => {
            let v = f32::from(bytes[0] as i8);
            if normalized {
                (v / 127.0).max(-1.0)
            } else {
                v
            }
        }
        DataType::U8 => {
            let v = f32::from(bytes[0]);
            if normalized {
                v / 255.0
            } else {
                v
            }
        }
        DataType::I16 => {
            let v = f32::from(i16::from_le_bytes([bytes[0], bytes[1]]));
            if normalized {
                (v / 32767.0).max(-1.0)
            } else {
                v
            }
        }
        DataType::U16 => {
            let v = f32::from(u16::from_le_bytes([bytes[0], bytes[1]]));
            if normalized {
                v / 65535.0
            } else {
                v
            }
        }
        DataType::U32 => read_uint(bytes) as f32,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_vertex_used_or_not() {
        assert!(uses_every_vertex(&[[0, 2, 1]], 3));
        assert!(!uses_every_vertex(&[[0, 2, 1]], 4));
        assert!(!uses_every_vertex(&[[0, 0, 1], [1, 0, 1]], 3));
        assert!(uses_every_vertex(&[], 0));
    }

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("a%20b.bin").as_deref(), Some("a b.bin"));
        assert_eq!(percent_decode("100%").as_deref(), Some("100%"));
        assert_eq!(percent_decode("%FF"), None);
    }

    #[test]
    fn uris_resolve_relative_to_the_file() {
        assert_eq!(
            resolve_uri(Path::new("m"), "x%20y.bin").expect("a percent-encoded relative URI resolves"),
            Path::new("m/x y.bin")
        );
        assert_eq!(
            resolve_uri(Path::new("m"), "file:///tmp/a.bin").expect("a file URI resolves"),
            Path::new("/tmp/a.bin")
        );
        assert!(resolve_uri(Path::new("m"), "https://example.com/a.bin").is_err());
    }

    #[test]
    fn colors_collapse_when_equal() {
        let red = Some([255, 0, 0, 255]);
        assert_eq!(mesh_colors(&[(0, None)], 3), None);
        assert_eq!(
            mesh_colors(&[(0, red), (2, red)], 3),
            Some(MeshColors::PerMesh([255, 0, 0, 255]))
        );
        assert_eq!(
            mesh_colors(&[(0, red), (1, None)], 3),
            Some(MeshColors::PerTriangle(vec![[255, 0, 0, 255], [255; 4], [255; 4]]))
        );
    }

    #[test]
    fn normalized_components() {
        assert_eq!(component(DataType::I8, true, &[0x81]), -1.0);
        assert_eq!(component(DataType::U16, true, &[0xff, 0xff]), 1.0);
        assert_eq!(component(DataType::U8, false, &[7]), 7.0);
        assert_eq!(component(DataType::F32, false, &1.5f32.to_le_bytes()), 1.5);
    }

    #[test]
    fn glb_header_checks() {
        let p = Path::new("x.glb");
        assert!(matches!(
            check_glb_header(p, b"glTF\x02\0\0\0"),
            Err(LoadError::Truncated { .. })
        ));
        assert!(matches!(
            check_glb_header(p, b"glTF\x02\0\0\0\x04\0\0\0"),
            Err(LoadError::Parse { .. })
        ));
        assert!(matches!(
            check_glb_header(p, b"glTF\x02\0\0\0\xff\0\0\0"),
            Err(LoadError::Truncated { .. })
        ));
        assert!(check_glb_header(p, b"{}").is_ok());
    }
}
