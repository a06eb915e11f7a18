//! The binary payload of a PLY file (little- and big-endian), read straight from the bytes.
//!
//! `ply-rs-bw` parses the header only. Each element's layout (the type and offset of every
//! scalar property, the count and item types of every list) is fixed from the header once;
//! then vertex coordinates go straight into the mesh's positions and face index lists into its
//! triangles, without a record or a `Vec` per element. Elements of fixed size (no lists) are
//! checked against the bytes left once for the whole element; elements with lists check each
//! list's bytes before reading it. Nothing is allocated beyond the positions and triangles,
//! whose counts `check_declared_counts` has held to the file's size.
//!
//! Errors name the file and the element (`face 2`): truncation, a negative or floating-point
//! list length, non-finite coordinates, indices out of range, data after the last element.

use std::marker::PhantomData;
use std::path::Path;

use occult_core::Vec3;
use ply_rs_bw::ply::{ElementDef, Encoding, Header, PropertyType, ScalarType};

use super::{Layout, MeshSink, Role, INDEX_LIST_NAMES};
use crate::load::{LoadError, Location};

/// A stored scalar type.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn of(t: &ScalarType) -> Self {
        match t {
            ScalarType::Char => Self::I8,
            ScalarType::UChar => Self::U8,
            ScalarType::Short => Self::I16,
            ScalarType::UShort => Self::U16,
            ScalarType::Int => Self::I32,
            ScalarType::UInt => Self::U32,
            ScalarType::Float => Self::F32,
            ScalarType::Double => Self::F64,
        }
    }

    fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    fn is_float(self) -> bool {
        matches!(self, Self::F32 | Self::F64)
    }

    /// The value at the start of `bytes` (at least [`Scalar::size`] long) as `f64`; `None` when
    /// `bytes` is shorter.
    fn f64_at<O: Order>(self, bytes: &[u8]) -> Option<f64> {
        Some(match self {
            Self::F32 => f64::from(f32::from_bits(O::u32(bytes)?)),
            Self::F64 => f64::from_bits(O::u64(bytes)?),
            _ => self.i64_at::<O>(bytes)? as f64,
        })
    }

    /// The integer at the start of `bytes` (floats truncated toward zero); `None` when `bytes`
    /// is shorter than the type.
    fn i64_at<O: Order>(self, bytes: &[u8]) -> Option<i64> {
        Some(match self {
            Self::I8 => i64::from(*bytes.first()? as i8),
            Self::U8 => i64::from(*bytes.first()?),
            Self::I16 => i64::from(O::u16(bytes)? as i16),
            Self::U16 => i64::from(O::u16(bytes)?),
            Self::I32 => i64::from(O::u32(bytes)? as i32),
            Self::U32 => i64::from(O::u32(bytes)?),
            Self::F32 | Self::F64 => self.f64_at::<O>(bytes)? as i64,
        })
    }
}

/// A byte order: the first bytes of a slice as an unsigned integer, `None` when it is shorter.
trait Order {
    fn u16(bytes: &[u8]) -> Option<u16>;
    fn u32(bytes: &[u8]) -> Option<u32>;
    fn u64(bytes: &[u8]) -> Option<u64>;
}

struct Little;
struct Big;

macro_rules! order {
    ($name:ident, $from:ident) => {
        impl Order for $name {
            #[inline(always)]
            fn u16(bytes: &[u8]) -> Option<u16> {
                Some(u16::$from(*bytes.first_chunk()?))
            }
            #[inline(always)]
            fn u32(bytes: &[u8]) -> Option<u32> {
                Some(u32::$from(*bytes.first_chunk()?))
            }
            #[inline(always)]
            fn u64(bytes: &[u8]) -> Option<u64> {
                Some(u64::$from(*bytes.first_chunk()?))
            }
        }
    };
}
order!(Little, from_le_bytes);
order!(Big, from_be_bytes);

/// An index type of a face list, read without a `match` per index.
trait Item {
    const SIZE: usize;
    /// The index at the start of `bytes`; `None` when `bytes` is shorter than [`Item::SIZE`].
    fn at<O: Order>(bytes: &[u8]) -> Option<i64>;
}

macro_rules! item {
    ($name:ident, $size:literal, |$b:ident, $o:ident| $read:expr) => {
        struct $name;
        impl Item for $name {
            const SIZE: usize = $size;
            #[inline(always)]
            fn at<$o: Order>($b: &[u8]) -> Option<i64> {
                Some(i64::from($read))
            }
        }
    };
}
item!(ItemI8, 1, |b, O| *b.first()? as i8);
item!(ItemU8, 1, |b, O| *b.first()?);
item!(ItemI16, 2, |b, O| O::u16(b)? as i16);
item!(ItemU16, 2, |b, O| O::u16(b)?);
item!(ItemI32, 4, |b, O| O::u32(b)? as i32);
item!(ItemU32, 4, |b, O| O::u32(b)?);

/// One property of an element, as laid out in the file.
#[derive(Clone, Copy, Debug)]
enum Field {
    /// A scalar; `axis` is 0, 1, 2 for a vertex's x, y, z.
    Scalar { kind: Scalar, axis: Option<usize> },
    /// A list: its length's type, its items' type, and whether it is the polygon's index list.
    List {
        count: Scalar,
        item: Scalar,
        is_index: bool,
    },
}

/// The layout of one element, fixed from the header.
struct ElementLayout<'h> {
    name: &'h str,
    count: usize,
    role: Role,
    fields: Vec<Field>,
    /// The property names, in the order of `fields` (for errors).
    names: Vec<&'h str>,
    /// The size of an element without lists, `None` with lists.
    stride: Option<usize>,
}

impl<'h> ElementLayout<'h> {
    fn of(name: &'h str, element: &'h ElementDef, role: Role) -> Self {
        let mut fields = Vec::with_capacity(element.properties.len());
        let mut names = Vec::with_capacity(element.properties.len());
        // The polygon's index list: the first of `INDEX_LIST_NAMES` the element has.
        let index_name = INDEX_LIST_NAMES
            .iter()
            .find(|n| element.properties.contains_key(**n))
            .copied();
        for (property, def) in &element.properties {
            let field = match &def.data_type {
                PropertyType::Scalar(t) => Field::Scalar {
                    kind: Scalar::of(t),
                    axis: match (role, property.as_str()) {
                        (Role::Vertex, "x") => Some(0),
                        (Role::Vertex, "y") => Some(1),
                        (Role::Vertex, "z") => Some(2),
                        _ => None,
                    },
                },
                PropertyType::List(count, item) => Field::List {
                    count: Scalar::of(count),
                    item: Scalar::of(item),
                    is_index: matches!(role, Role::Faces | Role::Strips) && Some(property.as_str()) == index_name,
                },
            };
            fields.push(field);
            names.push(property.as_str());
        }
        let stride = fields
            .iter()
            .map(|f| match f {
                Field::Scalar { kind, .. } => Some(kind.size()),
                Field::List { .. } => None,
            })
            .sum();
        Self {
            name,
            count: element.count,
            role,
            fields,
            names,
            stride,
        }
    }

    fn location(&self, index: usize) -> Location {
        Location::element(self.name, index as u64)
    }

    fn truncated(&self, path: &Path, index: usize) -> LoadError {
        LoadError::Truncated {
            path: path.to_path_buf(),
            location: self.location(index),
            message: format!("the header declares {} '{}' elements", self.count, self.name),
        }
    }

    fn parse_error(&self, path: &Path, index: usize, message: String) -> LoadError {
        LoadError::Parse {
            path: path.to_path_buf(),
            location: self.location(index),
            message,
        }
    }
}

/// Reads the binary payload after the header into `sink`.
///
/// # Errors
/// See the module doc.
pub(super) fn read_binary(
    path: &Path,
    header: &Header,
    layout: &Layout,
    payload: &[u8],
    sink: &mut MeshSink<'_>,
) -> Result<(), LoadError> {
    let big_endian = header.encoding == Encoding::BinaryBigEndian;
    let mut rest = payload;
    for (name, element) in &header.elements {
        let element = ElementLayout::of(name, element, layout.role(name));
        rest = if big_endian {
            read_element::<Big>(path, &element, rest, sink)?
        } else {
            read_element::<Little>(path, &element, rest, sink)?
        };
    }
    if !rest.is_empty() {
        return Err(LoadError::CountMismatch {
            path: path.to_path_buf(),
            location: Location::File,
            message: format!("{} bytes follow the last element the header declares", rest.len()),
        });
    }
    Ok(())
}

/// Reads the elements of `element` at the start of `bytes`; returns the bytes after them.
fn read_element<'b, O: Order>(
    path: &Path,
    element: &ElementLayout<'_>,
    bytes: &'b [u8],
    sink: &mut MeshSink<'_>,
) -> Result<&'b [u8], LoadError> {
    if element.count == 0 {
        return Ok(bytes);
    }
    for (field, property) in element.fields.iter().zip(&element.names) {
        if let Field::List { count, .. } = field {
            if count.is_float() {
                return Err(element.parse_error(
                    path,
                    0,
                    format!("list '{property}' has a floating-point length type"),
                ));
            }
        }
    }
    match (element.stride, element.role) {
        (Some(stride), role) => {
            // Fixed size: one check for the whole element.
            let need = element.count.checked_mul(stride).filter(|&n| n <= bytes.len());
            let Some(need) = need else {
                return Err(element.truncated(path, bytes.len() / stride.max(1)));
            };
            let (body, rest) = bytes.split_at(need);
            if role == Role::Vertex {
                read_fixed_vertices::<O>(path, element, body, stride, sink)?;
            }
            // Other fixed elements are skipped whole; a face or strip element without a list
            // was refused by `Layout::of`.
            Ok(rest)
        }
        (None, Role::Faces) => match single_index_list(element) {
            Some((item, before, count, after)) => {
                read_simple_faces::<O>(path, element, bytes, item, before, count, after, sink)
            }
            None => read_general::<O>(path, element, bytes, sink),
        },
        (None, _) => read_general::<O>(path, element, bytes, sink),
    }
}

/// Vertices of fixed size: x, y, z at their offsets, straight into the positions.
fn read_fixed_vertices<O: Order>(
    path: &Path,
    element: &ElementLayout<'_>,
    body: &[u8],
    stride: usize,
    sink: &mut MeshSink<'_>,
) -> Result<(), LoadError> {
    let mut axes = [(0, Scalar::F32); 3];
    let mut offset = 0;
    for field in &element.fields {
        if let Field::Scalar { kind, axis } = *field {
            if let Some(axis) = axis {
                axes[axis] = (offset, kind);
            }
            offset += kind.size();
        }
    }
    let all_f32 = axes.iter().all(|&(_, kind)| kind == Scalar::F32);
    let bad_record = |index| element.parse_error(path, index, "record shorter than its layout".into());
    if stride == 0 {
        return Err(bad_record(0));
    }
    for (index, record) in body.chunks_exact(stride).enumerate() {
        let p = if all_f32 {
            let axis = |a: usize| record.get(axes[a].0..).and_then(O::u32).map(f32::from_bits);
            match (axis(0), axis(1), axis(2)) {
                (Some(x), Some(y), Some(z)) => Vec3::new(x, y, z),
                _ => return Err(bad_record(index)),
            }
        } else {
            let axis = |a: usize| {
                let (at, kind) = axes[a];
                record.get(at..).and_then(|b| kind.f64_at::<O>(b))
            };
            match (axis(0), axis(1), axis(2)) {
                (Some(x), Some(y), Some(z)) => Vec3::new(x as f32, y as f32, z as f32),
                _ => return Err(bad_record(index)),
            }
        };
        if p.is_finite() {
            sink.positions.push(p);
        } else {
            // Names the coordinate and the element.
            sink.vertex([p.x, p.y, p.z].map(f64::from), || element.location(index))?;
        }
    }
    Ok(())
}

/// When the element's only list is its index list, with integer items: the item type and the
/// bytes of the scalars before and after it, and the list's length type.
fn single_index_list(element: &ElementLayout<'_>) -> Option<(Scalar, usize, Scalar, usize)> {
    let mut before = 0;
    let mut after = 0;
    let mut list = None;
    for field in &element.fields {
        match *field {
            Field::Scalar { kind, .. } if list.is_none() => before += kind.size(),
            Field::Scalar { kind, .. } => after += kind.size(),
            Field::List {
                count,
                item,
                is_index: true,
            } if list.is_none() && !item.is_float() => list = Some((item, count)),
            Field::List { .. } => return None,
        }
    }
    let (item, count) = list?;
    Some((item, before, count, after))
}

/// Faces whose only list is the index list: dispatches on the index type once.
#[allow(clippy::too_many_arguments)]
fn read_simple_faces<'b, O: Order>(
    path: &Path,
    element: &ElementLayout<'_>,
    bytes: &'b [u8],
    item: Scalar,
    before: usize,
    count: Scalar,
    after: usize,
    sink: &mut MeshSink<'_>,
) -> Result<&'b [u8], LoadError> {
    let faces = SimpleFaces {
        path,
        element,
        before,
        count,
        after,
        order: PhantomData::<O>,
    };
    match item {
        Scalar::I8 => faces.read::<ItemI8>(bytes, sink),
        Scalar::U8 => faces.read::<ItemU8>(bytes, sink),
        Scalar::I16 => faces.read::<ItemI16>(bytes, sink),
        Scalar::U16 => faces.read::<ItemU16>(bytes, sink),
        Scalar::I32 => faces.read::<ItemI32>(bytes, sink),
        Scalar::U32 => faces.read::<ItemU32>(bytes, sink),
        // `single_index_list` takes integer items only.
        Scalar::F32 | Scalar::F64 => read_general::<O>(path, element, bytes, sink),
    }
}

/// A face element of fixed scalars around one index list.
struct SimpleFaces<'a, 'h, O> {
    path: &'a Path,
    element: &'a ElementLayout<'h>,
    /// Bytes of the scalars before the list.
    before: usize,
    /// The list length's type.
    count: Scalar,
    /// Bytes of the scalars after the list.
    after: usize,
    order: PhantomData<O>,
}

impl<O: Order> SimpleFaces<'_, '_, O> {
    fn read<'b, I: Item>(&self, mut bytes: &'b [u8], sink: &mut MeshSink<'_>) -> Result<&'b [u8], LoadError> {
        let element = self.element;
        let count_size = self.count.size();
        let vertex_count = sink.vertex_count as u64;
        // Bounded: `check_declared_counts` held the face count to the file's size.
        sink.triangles.reserve(element.count);
        let mut corners: Vec<i64> = Vec::new();
        for index in 0..element.count {
            let Some(length) = bytes.get(self.before..).and_then(|b| self.count.i64_at::<O>(b)) else {
                return Err(element.truncated(self.path, index));
            };
            let Ok(length) = usize::try_from(length) else {
                return Err(self.negative_length(index, length));
            };
            let start = self.before + count_size;
            let end = length
                .checked_mul(I::SIZE)
                .and_then(|n| n.checked_add(start))
                .filter(|&end| end.saturating_add(self.after) <= bytes.len());
            let Some(end) = end else {
                return Err(element.truncated(self.path, index));
            };
            let list = &bytes[start..end];
            if length == 3 {
                let corner = |k: usize| list.get(k * I::SIZE..).and_then(I::at::<O>);
                let (Some(a), Some(b), Some(c)) = (corner(0), corner(1), corner(2)) else {
                    return Err(element.truncated(self.path, index));
                };
                // Negative indices wrap to values above every vertex count.
                if (a as u64) < vertex_count && (b as u64) < vertex_count && (c as u64) < vertex_count {
                    sink.triangles.push([a as u32, b as u32, c as u32]);
                } else {
                    sink.face(&[a, b, c], || element.location(index))?;
                }
            } else {
                corners.clear();
                corners.extend(list.chunks_exact(I::SIZE).filter_map(I::at::<O>));
                sink.face(&corners, || element.location(index))?;
            }
            bytes = &bytes[end + self.after..];
        }
        Ok(bytes)
    }

    fn negative_length(&self, index: usize, length: i64) -> LoadError {
        let property = self
            .element
            .fields
            .iter()
            .zip(&self.element.names)
            .find(|(f, _)| matches!(f, Field::List { is_index: true, .. }))
            .map_or("", |(_, n)| n);
        self.element.parse_error(
            self.path,
            index,
            format!("list '{property}' has a negative length ({length})"),
        )
    }
}

/// Any element, one property after another: lists other than the index list are skipped,
/// scalars other than a vertex's coordinates too.
fn read_general<'b, O: Order>(
    path: &Path,
    element: &ElementLayout<'_>,
    mut bytes: &'b [u8],
    sink: &mut MeshSink<'_>,
) -> Result<&'b [u8], LoadError> {
    let mut indices: Vec<i64> = Vec::new();
    for index in 0..element.count {
        let mut xyz = [0.0f64; 3];
        indices.clear();
        for (field, property) in element.fields.iter().zip(&element.names) {
            match *field {
                Field::Scalar { kind, axis } => {
                    let Some(value) = kind.f64_at::<O>(bytes) else {
                        return Err(element.truncated(path, index));
                    };
                    if let Some(axis) = axis {
                        xyz[axis] = value;
                    }
                    bytes = &bytes[kind.size()..];
                }
                Field::List { count, item, is_index } => {
                    let Some(length) = count.i64_at::<O>(bytes) else {
                        return Err(element.truncated(path, index));
                    };
                    let Ok(length) = usize::try_from(length) else {
                        return Err(element.parse_error(
                            path,
                            index,
                            format!("list '{property}' has a negative length ({length})"),
                        ));
                    };
                    bytes = &bytes[count.size()..];
                    let size = length.checked_mul(item.size()).filter(|&n| n <= bytes.len());
                    let Some(size) = size else {
                        return Err(element.truncated(path, index));
                    };
                    let (list, rest) = bytes.split_at(size);
                    if is_index {
                        // Bounded by the bytes just checked.
                        indices.extend(list.chunks_exact(item.size()).filter_map(|b| item.i64_at::<O>(b)));
                    }
                    bytes = rest;
                }
            }
        }
        let location = || element.location(index);
        match element.role {
            Role::Vertex => sink.vertex(xyz, location)?,
            Role::Faces => sink.face(&indices, location)?,
            Role::Strips => sink.strips(&indices, location)?,
            Role::Other => {}
        }
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalars_read_in_both_orders() {
        let bytes = [0x80, 0x01, 0x00, 0x00, 0, 0, 0, 0];
        assert_eq!(Scalar::I16.i64_at::<Little>(&bytes), Some(0x0180));
        assert_eq!(Scalar::I16.i64_at::<Big>(&bytes), Some(-0x7fff));
        assert_eq!(Scalar::U8.i64_at::<Big>(&bytes), Some(0x80));
        assert_eq!(Scalar::I8.i64_at::<Big>(&bytes), Some(-0x80));
        assert_eq!(Scalar::U32.i64_at::<Big>(&bytes), Some(0x8001_0000));
        assert_eq!(Scalar::I32.i64_at::<Big>(&bytes), Some(-0x7fff_0000));
        assert_eq!(Scalar::F64.f64_at::<Little>(&bytes[..7]), None);
        assert_eq!(Scalar::F32.f64_at::<Big>(&1.5f32.to_be_bytes()), Some(1.5));
        assert_eq!(ItemU16::at::<Little>(&[1]), None);
        assert_eq!(ItemI32::at::<Little>(&(-2i32).to_le_bytes()), Some(-2));
    }

    use crate::load::ply::ply_from_bytes;
    use crate::load::LoadedScene;

    /// A binary PLY of `header` lines (after the format line) and `body`.
    fn ply(big_endian: bool, header: &str, body: &[u8]) -> Vec<u8> {
        let order = if big_endian { "big" } else { "little" };
        let mut bytes = format!("ply\nformat binary_{order}_endian 1.0\n{header}end_header\n").into_bytes();
        bytes.extend_from_slice(body);
        bytes
    }

    fn load(bytes: &[u8]) -> Result<LoadedScene, LoadError> {
        ply_from_bytes(Path::new("t.ply"), bytes)
    }

    fn mesh_of(loaded: &LoadedScene) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        let mesh = loaded.scene.node(loaded.scene.root()).mesh().expect("one mesh");
        let positions = mesh.positions().iter().map(|p| p.to_array()).collect();
        (positions, mesh.triangles().to_vec())
    }

    const TRIANGLE: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

    #[test]
    fn strips_in_big_endian() {
        let header = "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
                      element tristrips 1\nproperty list int int vertex_indices\n";
        let mut body = Vec::new();
        for p in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.], [1., 1., 0.]] {
            p.iter().for_each(|c| body.extend(c.to_be_bytes()));
        }
        for i in [7i32, 0, 1, 2, 3, -1, 0, 1] {
            body.extend(i.to_be_bytes());
        }
        let loaded = load(&ply(true, header, &body)).expect("strips load");
        assert_eq!(mesh_of(&loaded).1, [[0, 1, 2], [2, 1, 3]]);
    }

    #[test]
    fn lists_anywhere_and_doubles_take_the_general_path() {
        // A vertex with a list before its double coordinates; a face with a list before its
        // index list; quads fanned; a face of two corners counted.
        let header = "element vertex 3\nproperty list uchar short notes\nproperty double x\n\
                      property double y\nproperty double z\nelement face 2\nproperty list ushort uchar tags\n\
                      property list uint ushort vertex_index\n";
        let mut body = Vec::new();
        for (k, p) in TRIANGLE.iter().enumerate() {
            body.push(k as u8);
            body.extend(std::iter::repeat_n(9u8, 2 * k));
            p.iter().for_each(|&c| body.extend(f64::from(c).to_le_bytes()));
        }
        body.extend([1, 0, 5]);
        body.extend(4u32.to_le_bytes());
        [0u16, 1, 2, 0].iter().for_each(|i| body.extend(i.to_le_bytes()));
        body.extend([0, 0]);
        body.extend(2u32.to_le_bytes());
        [0u16, 1].iter().for_each(|i| body.extend(i.to_le_bytes()));
        let loaded = load(&ply(false, header, &body)).expect("general layout loads");
        let (positions, triangles) = mesh_of(&loaded);
        assert_eq!(positions, TRIANGLE);
        assert_eq!(triangles, [[0, 1, 2], [0, 2, 0]]);
        assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
    }

    /// The error of a binary little-endian triangle of `index_list` (`list TYPE TYPE
    /// vertex_indices`) with faces whose bytes are `faces`.
    fn face_case(index_list: &str, faces: &[u8]) -> String {
        let header = format!(
            "element vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 2\n\
             property {index_list}\n"
        );
        let mut body = Vec::new();
        TRIANGLE.iter().flatten().for_each(|c| body.extend(c.to_le_bytes()));
        body.extend(faces);
        load(&ply(false, &header, &body)).expect_err("a bad face").to_string()
    }

    #[test]
    fn bad_faces_name_the_element() {
        let e = face_case("list char uchar vertex_indices", &[3, 0, 1, 2, 0xff, 0, 1, 2]);
        assert_eq!(e, "t.ply: face 1: list 'vertex_indices' has a negative length (-1)");
        let e = face_case("list uchar uchar vertex_indices", &[3, 0, 1, 2, 3, 0, 1, 3]);
        assert!(e.starts_with("t.ply: face 1: ") && e.contains("index 3"), "{e}");
        let mut negative = vec![3];
        [0i32, 1, 2].iter().for_each(|i| negative.extend(i.to_le_bytes()));
        negative.push(3);
        [0i32, -1, 2].iter().for_each(|i| negative.extend(i.to_le_bytes()));
        let e = face_case("list uchar int vertex_indices", &negative);
        assert!(e.starts_with("t.ply: face 1: ") && e.contains("index -1"), "{e}");
        let e = face_case("list uchar uchar vertex_indices", &[3, 0, 1, 2, 200, 0, 1, 2]);
        assert!(e.starts_with("t.ply: face 1: file is truncated"), "{e}");
        let e = face_case("list float uchar vertex_indices", &[0; 8]);
        assert!(e.contains("face 0") && e.contains("floating-point length"), "{e}");
    }

    #[test]
    fn a_cut_vertex_is_named() {
        // Faces first: the declared sizes (4 + 36 bytes at least) fit the 4 + 33 bytes there are
        // only because a list's minimum is its count; vertex 2 is cut short.
        let header = "element face 1\nproperty list uchar uchar vertex_indices\nelement vertex 3\n\
                      property float x\nproperty float y\nproperty float z\n";
        let mut body = vec![3, 0, 1, 2];
        body.extend([0u8; 33]);
        let e = load(&ply(false, header, &body)).expect_err("cut").to_string();
        assert!(e.starts_with("t.ply: vertex 2: file is truncated"), "{e}");
    }
}
