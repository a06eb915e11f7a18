//! glTF `EXT_meshopt_compression`: buffer views stored compressed by meshoptimizer's codecs
//! (what `gltfpack -c` writes), decoded with the `meshopt` crate.
//!
//! # References
//! - Khronos Group, *EXT_meshopt_compression* (glTF 2.0 vendor extension): the buffer-view
//!   extension object (`buffer`, `byteOffset`, `byteLength`, `byteStride`, `count`, `mode`,
//!   `filter`), the modes `ATTRIBUTES`, `TRIANGLES` and `INDICES` and their stride rules, the
//!   filters `NONE`, `OCTAHEDRAL`, `QUATERNION` and `EXPONENTIAL`, and fallback buffers (a
//!   buffer marked `"fallback": true` need not have data; a loader that decodes never reads it).
//! - Arseny Kapoulkine, meshoptimizer's `vertexcodec.cpp`, `indexcodec.cpp` and
//!   `vertexfilter.cpp`: the bitstreams and filters themselves.
//!
//! A compressed view decodes to `count * byteStride` bytes, which then stand for the view's
//! bytes: accessors read them as they read any view. Everything the extension object declares is
//! checked before the decoder runs, since meshoptimizer asserts on strides and counts outside the
//! codec's rules (an abort, not an error). The size is bounded **before** allocating: no mode
//! expands more than [`MAX_EXPANSION`] times (attributes at best 1024-fold in version 1 of the
//! codec, index buffers 12-fold, index sequences 4-fold), so a view declaring more is refused.
//!
//! Cost: the codecs decode at several GB/s; a filter adds one pass over the decoded bytes (and,
//! to keep this module free of `unsafe`, one copy into typed lanes and back).

use serde_json::Value;

/// The extension's name, as `extensionsUsed` and the buffer-view objects carry it.
pub(super) const EXTENSION: &str = "EXT_meshopt_compression";

/// The most bytes one compressed byte decodes to, in any mode: attribute blocks of 256 vertices
/// whose byte channels are all constant cost one 2-bit control field per channel in version 1
/// of the codec (256 bytes out per quarter byte in).
pub(super) const MAX_EXPANSION: u64 = 1024;

/// How the bytes of a view were encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Mode {
    /// Vertex attributes (`meshopt_encodeVertexBuffer`); stride a multiple of 4, at most 256.
    Attributes,
    /// A triangle list (`meshopt_encodeIndexBuffer`); stride 2 or 4, count a multiple of 3.
    Triangles,
    /// Any index sequence (`meshopt_encodeIndexSequence`); stride 2 or 4.
    Indices,
}

impl Mode {
    /// The name the extension gives it.
    fn name(self) -> &'static str {
        match self {
            Mode::Attributes => "ATTRIBUTES",
            Mode::Triangles => "TRIANGLES",
            Mode::Indices => "INDICES",
        }
    }
}

/// What is applied to attributes after decoding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Filter {
    /// None.
    None,
    /// Octahedral unit vectors (normals, tangents); stride 4 (8-bit) or 8 (16-bit).
    Octahedral,
    /// Quaternions of 16-bit components; stride 8.
    Quaternion,
    /// Floats as 8-bit exponent and 24-bit mantissa, per 32-bit component; stride a multiple of 4.
    Exponential,
}

/// A buffer view's `EXT_meshopt_compression` object, checked against the extension's rules.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct CompressedView {
    /// The buffer holding the compressed bytes.
    pub buffer_index: usize,
    /// Where they start in it.
    pub byte_offset: usize,
    /// How many there are.
    pub byte_length: usize,
    /// The size of one decoded element, in bytes.
    pub byte_stride: usize,
    /// The number of decoded elements.
    pub count: usize,
    pub mode: Mode,
    pub filter: Filter,
}

impl Filter {
    /// The name the extension gives it.
    fn name(self) -> &'static str {
        match self {
            Filter::None => "NONE",
            Filter::Octahedral => "OCTAHEDRAL",
            Filter::Quaternion => "QUATERNION",
            Filter::Exponential => "EXPONENTIAL",
        }
    }
}

impl CompressedView {
    /// Reads and checks the extension object of a buffer view.
    ///
    /// # Errors
    /// A message naming the field at fault: a missing or non-integer field, an unknown mode or
    /// filter, a stride or count the mode does not allow, a filter the mode or stride does not
    /// allow, or a decoded size beyond [`MAX_EXPANSION`] times the compressed bytes.
    pub fn parse(object: &Value) -> Result<Self, String> {
        let integer = |name: &str, default: Option<usize>| -> Result<usize, String> {
            match object.get(name) {
                None => default.ok_or_else(|| format!("{EXTENSION}: no '{name}'")),
                Some(value) => value
                    .as_u64()
                    .and_then(|v| usize::try_from(v).ok())
                    .ok_or_else(|| format!("{EXTENSION}: '{name}' is not a non-negative integer: {value}")),
            }
        };
        let mode = match object.get("mode").and_then(Value::as_str) {
            Some("ATTRIBUTES") => Mode::Attributes,
            Some("TRIANGLES") => Mode::Triangles,
            Some("INDICES") => Mode::Indices,
            other => return Err(format!("{EXTENSION}: unknown mode {other:?}")),
        };
        let filter = match object.get("filter").map(|f| f.as_str()) {
            None | Some(Some("NONE")) => Filter::None,
            Some(Some("OCTAHEDRAL")) => Filter::Octahedral,
            Some(Some("QUATERNION")) => Filter::Quaternion,
            Some(Some("EXPONENTIAL")) => Filter::Exponential,
            Some(other) => return Err(format!("{EXTENSION}: unknown filter {other:?}")),
        };
        let view = Self {
            buffer_index: integer("buffer", None)?,
            byte_offset: integer("byteOffset", Some(0))?,
            byte_length: integer("byteLength", None)?,
            byte_stride: integer("byteStride", None)?,
            count: integer("count", None)?,
            mode,
            filter,
        };
        view.check()?;
        Ok(view)
    }

    /// The extension's rules on strides, counts and filters, and the size bound.
    fn check(&self) -> Result<(), String> {
        let stride = self.byte_stride;
        let stride_ok = match self.mode {
            Mode::Attributes => stride > 0 && stride <= 256 && stride.is_multiple_of(4),
            Mode::Triangles | Mode::Indices => stride == 2 || stride == 4,
        };
        if !stride_ok {
            return Err(format!(
                "{EXTENSION}: byteStride {stride} is not allowed in mode {}",
                self.mode.name()
            ));
        }
        if self.mode == Mode::Triangles && !self.count.is_multiple_of(3) {
            return Err(format!(
                "{EXTENSION}: count {} of mode TRIANGLES is not a multiple of 3",
                self.count
            ));
        }
        let filter_ok = match self.filter {
            Filter::None => true,
            _ if self.mode != Mode::Attributes => false,
            Filter::Octahedral => stride == 4 || stride == 8,
            Filter::Quaternion => stride == 8,
            Filter::Exponential => true,
        };
        if !filter_ok {
            return Err(format!(
                "{EXTENSION}: filter {} is not allowed with mode {} and byteStride {stride}",
                self.filter.name(),
                self.mode.name()
            ));
        }
        let decoded = self.count as u128 * stride as u128;
        if decoded > u128::from(MAX_EXPANSION) * self.byte_length as u128 {
            return Err(format!(
                "{EXTENSION}: {} elements of {stride} bytes ({decoded} bytes) cannot come from {} compressed bytes \
                 (the codecs expand at most {MAX_EXPANSION}-fold)",
                self.count, self.byte_length
            ));
        }
        Ok(())
    }

    /// The size of the decoded view, in bytes (bounded by [`CompressedView::parse`]).
    pub fn decoded_len(&self) -> usize {
        self.count * self.byte_stride
    }

    /// Decodes `compressed` (the `byte_length` bytes the object names) into the view's bytes,
    /// `count * byte_stride` of them, filter applied.
    ///
    /// # Errors
    /// The decoder's refusal of malformed or truncated data, as a message.
    pub fn decode(&self, compressed: &[u8]) -> Result<Vec<u8>, String> {
        let refused = |e: meshopt::Error| format!("{EXTENSION}: the {} data does not decode ({e})", self.mode.name());
        let mut bytes = match (self.mode, self.byte_stride) {
            (Mode::Attributes, stride) => decode_attributes(compressed, self.count, stride).map_err(refused)?,
            (Mode::Triangles, 2) => {
                le_bytes(meshopt::decode_index_buffer::<u16>(compressed, self.count).map_err(refused)?)
            }
            (Mode::Triangles, _) => {
                le_bytes(meshopt::decode_index_buffer::<u32>(compressed, self.count).map_err(refused)?)
            }
            (Mode::Indices, 2) => {
                le_bytes(meshopt::decode_index_sequence::<u16>(compressed, self.count).map_err(refused)?)
            }
            (Mode::Indices, _) => {
                le_bytes(meshopt::decode_index_sequence::<u32>(compressed, self.count).map_err(refused)?)
            }
        };
        apply_filter(self.filter, self.byte_stride, &mut bytes);
        Ok(bytes)
    }
}

/// One decoded vertex of `N` bytes (arrays past 32 have no `Default`, which the crate needs).
#[derive(Clone, Copy)]
#[repr(transparent)]
struct VertexBytes<const N: usize>([u8; N]);

impl<const N: usize> Default for VertexBytes<N> {
    fn default() -> Self {
        Self([0; N])
    }
}

fn attributes_of<const N: usize>(compressed: &[u8], count: usize) -> Result<Vec<u8>, meshopt::Error> {
    let vertices = meshopt::decode_vertex_buffer::<VertexBytes<N>>(compressed, count)?;
    // Same size and alignment: the collect reuses the allocation.
    let arrays: Vec<[u8; N]> = vertices.into_iter().map(|v| v.0).collect();
    Ok(arrays.into_flattened())
}

/// `meshopt_decodeVertexBuffer` for a stride known only at run time (a multiple of 4 up to 256,
/// checked by [`CompressedView::check`]).
fn decode_attributes(compressed: &[u8], count: usize, stride: usize) -> Result<Vec<u8>, meshopt::Error> {
    macro_rules! by_stride {
        ($($n:literal)+) => {
            match stride {
                $($n => attributes_of::<$n>(compressed, count),)+
                _ => Err(meshopt::Error::Parse(format!("byteStride {stride}"))),
            }
        };
    }
    by_stride!(4 8 12 16 20 24 28 32 36 40 44 48 52 56 60 64 68 72 76 80 84 88 92 96 100 104 108 112 116
        120 124 128 132 136 140 144 148 152 156 160 164 168 172 176 180 184 188 192 196 200 204 208 212
        216 220 224 228 232 236 240 244 248 252 256)
}

/// Integers as their little-endian bytes, as a glTF buffer holds them.
fn le_bytes<T: Copy + LeBytes>(values: Vec<T>) -> Vec<u8> {
    let mut out = Vec::with_capacity(values.len() * std::mem::size_of::<T>());
    for v in values {
        v.extend_le(&mut out);
    }
    out
}

trait LeBytes {
    fn extend_le(self, out: &mut Vec<u8>);
}

impl LeBytes for u16 {
    fn extend_le(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

impl LeBytes for u32 {
    fn extend_le(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

/// Applies `filter` in place to decoded attributes of `stride` bytes (strides checked by
/// [`CompressedView::check`]).
fn apply_filter(filter: Filter, stride: usize, bytes: &mut [u8]) {
    match (filter, stride) {
        (Filter::None, _) => {}
        (Filter::Octahedral, 4) => {
            let mut lanes: Vec<[i8; 4]> = bytes
                .chunks_exact(4)
                .map(|c| [0, 1, 2, 3].map(|k| c[k] as i8))
                .collect();
            meshopt::decode_filter_oct(&mut lanes);
            for (c, lane) in bytes.chunks_exact_mut(4).zip(lanes) {
                c.copy_from_slice(&lane.map(|v| v as u8));
            }
        }
        (Filter::Octahedral | Filter::Quaternion, _) => {
            let mut lanes: Vec<[i16; 4]> = bytes
                .chunks_exact(8)
                .map(|c| [0, 1, 2, 3].map(|k| i16::from_le_bytes([c[2 * k], c[2 * k + 1]])))
                .collect();
            if filter == Filter::Octahedral {
                meshopt::decode_filter_oct(&mut lanes);
            } else {
                meshopt::decode_filter_quat(&mut lanes);
            }
            for (c, lane) in bytes.chunks_exact_mut(8).zip(lanes) {
                for (k, v) in lane.into_iter().enumerate() {
                    c[2 * k..2 * k + 2].copy_from_slice(&v.to_le_bytes());
                }
            }
        }
        (Filter::Exponential, _) => {
            // Each 32-bit component is decoded on its own, whatever the stride.
            let mut lanes: Vec<[u32; 1]> = bytes
                .chunks_exact(4)
                .map(|c| [u32::from_le_bytes([c[0], c[1], c[2], c[3]])])
                .collect();
            meshopt::decode_filter_exp(&mut lanes);
            for (c, lane) in bytes.chunks_exact_mut(4).zip(lanes) {
                c.copy_from_slice(&lane[0].to_le_bytes());
            }
        }
    }
}

/// Whether a buffer's extension object marks it as a fallback (data that need not exist).
pub(super) fn is_fallback(object: Option<&Value>) -> bool {
    object
        .and_then(|o| o.get("fallback"))
        .and_then(Value::as_bool)
        .unwrap_or(false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn attributes_round_trip_at_odd_strides() {
        for stride in [4usize, 12, 36, 256] {
            let count = 37;
            let data: Vec<u8> = (0..count * stride).map(|i| (i * 7 % 251) as u8).collect();
            let encoded = match stride {
                4 => meshopt::encode_vertex_buffer(
                    &data
                        .chunks_exact(4)
                        .map(|c| [c[0], c[1], c[2], c[3]])
                        .collect::<Vec<_>>(),
                ),
                _ => {
                    let vertices: Vec<Vec<u8>> = data.chunks_exact(stride).map(<[u8]>::to_vec).collect();
                    // Encode through the same generic path as decoding, one stride at a time.
                    encode_bytes(&vertices, stride)
                }
            }
            .expect("encodes");
            let view = CompressedView {
                buffer_index: 0,
                byte_offset: 0,
                byte_length: encoded.len(),
                byte_stride: stride,
                count,
                mode: Mode::Attributes,
                filter: Filter::None,
            };
            assert_eq!(view.decode(&encoded).expect("decodes"), data, "stride {stride}");
        }
    }

    fn encode_bytes(vertices: &[Vec<u8>], stride: usize) -> meshopt::Result<Vec<u8>> {
        fn typed<const N: usize>(vertices: &[Vec<u8>]) -> meshopt::Result<Vec<u8>> {
            let typed: Vec<[u8; N]> = vertices
                .iter()
                .map(|v| v.as_slice().try_into().expect("stride"))
                .collect();
            meshopt::encode_vertex_buffer(&typed)
        }
        match stride {
            12 => typed::<12>(vertices),
            36 => typed::<36>(vertices),
            256 => typed::<256>(vertices),
            _ => unreachable!("stride {stride} not in the test"),
        }
    }

    #[test]
    fn triangles_and_sequences_round_trip() {
        let indices: Vec<u32> = vec![0, 1, 2, 2, 1, 3, 3, 1, 4, 70000, 2, 4];
        let encoded = meshopt::encode_index_buffer(&indices, 70001).expect("encodes");
        let mut view = CompressedView {
            buffer_index: 0,
            byte_offset: 0,
            byte_length: encoded.len(),
            byte_stride: 4,
            count: indices.len(),
            mode: Mode::Triangles,
            filter: Filter::None,
        };
        let bytes = view.decode(&encoded).expect("decodes");
        let decoded: Vec<u32> = bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        assert_eq!(decoded, indices);

        let sequence: Vec<u32> = vec![5, 4, 3, 9, 1000];
        let encoded = meshopt::encode_index_sequence(&sequence, 1001).expect("encodes");
        view.mode = Mode::Indices;
        view.byte_stride = 2;
        view.count = sequence.len();
        view.byte_length = encoded.len();
        let bytes = view.decode(&encoded).expect("decodes");
        let decoded: Vec<u32> = bytes
            .chunks_exact(2)
            .map(|c| u32::from(u16::from_le_bytes([c[0], c[1]])))
            .collect();
        assert_eq!(decoded, sequence);
    }

    #[test]
    fn exponential_filter_restores_floats() {
        let values = [[1.5f32, -2.25, 1024.0, 0.0]];
        let encoded = meshopt::encode_filter_exp(&values, 24, meshopt::EncodeExpMode::Separate);
        let mut bytes: Vec<u8> = encoded.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        apply_filter(Filter::Exponential, 16, &mut bytes);
        let floats: Vec<f32> = bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        assert_eq!(floats, values[0]);
    }

    #[test]
    fn objects_breaking_the_rules_are_refused() {
        let ok = json!({"buffer": 0, "byteLength": 100, "byteStride": 12, "count": 10, "mode": "ATTRIBUTES"});
        assert!(CompressedView::parse(&ok).is_ok());
        let with = |key: &str, value: Value| {
            let mut o = ok.clone();
            o[key] = value;
            CompressedView::parse(&o).expect_err("refused")
        };
        assert!(with("byteStride", json!(6)).contains("byteStride 6"));
        assert!(with("byteStride", json!(260)).contains("byteStride 260"));
        assert!(with("mode", json!("STRIPS")).contains("unknown mode"));
        assert!(with("filter", json!("QUATERNION")).contains("filter QUATERNION"));
        assert!(with("count", json!(-1)).contains("'count'"));
        assert!(with("count", json!(1u64 << 40)).contains("cannot come from"));
        let triangles = json!({"buffer": 0, "byteLength": 100, "byteStride": 4, "count": 10, "mode": "TRIANGLES"});
        assert!(CompressedView::parse(&triangles)
            .expect_err("refused")
            .contains("multiple of 3"));
        assert!(is_fallback(Some(&json!({"fallback": true}))));
        assert!(!is_fallback(None));
    }

    #[test]
    fn garbage_is_an_error_never_a_panic() {
        let view = CompressedView {
            buffer_index: 0,
            byte_offset: 0,
            byte_length: 8,
            byte_stride: 4,
            count: 300,
            mode: Mode::Triangles,
            filter: Filter::None,
        };
        for garbage in [&[][..], &[0xff; 8], &[0xe1, 0, 0, 0, 0, 0, 0, 0]] {
            assert!(view.decode(garbage).is_err());
        }
        let attributes = CompressedView {
            mode: Mode::Attributes,
            count: 3,
            ..view
        };
        assert!(attributes.decode(&[0xa0, 1, 2]).is_err());
    }
}
