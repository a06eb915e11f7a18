//! Typed errors of the core layer.

use thiserror::Error;

/// Result with [`CoreError`].
pub type Result<T, E = CoreError> = std::result::Result<T, E>;

/// Bad scene or camera data. Every variant names the element at fault.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CoreError {
    /// A vertex coordinate is NaN or infinite.
    #[error("vertex {vertex_index} has a non-finite coordinate {value:?}")]
    NonFiniteVertex {
        /// Index of the offending vertex.
        vertex_index: usize,
        /// Its position.
        value: [f32; 3],
    },
    /// A triangle refers to a vertex that does not exist.
    #[error("triangle {triangle_index} refers to vertex {vertex_index}, but the mesh has {vertex_count} vertices")]
    IndexOutOfRange {
        /// Index of the offending triangle.
        triangle_index: usize,
        /// The index it holds.
        vertex_index: u32,
        /// Number of vertices in the mesh.
        vertex_count: usize,
    },
    /// Per-triangle colors do not match the triangle count.
    #[error("mesh has {triangle_count} triangles but {color_count} per-triangle colors")]
    ColorCountMismatch {
        /// Triangles in the mesh.
        triangle_count: usize,
        /// Colors given.
        color_count: usize,
    },
    /// A mesh holds more vertices than a `u32` index can name.
    #[error("mesh has {0} vertices, more than 32-bit indices can address")]
    TooManyVertices(usize),
    /// The scene (or a node built for it) has no triangle.
    #[error("scene is empty: {0}")]
    EmptyScene(String),
    /// An instance refers to a node that does not exist (yet).
    #[error("instance {instance_index} of group '{group}' refers to node {child}, which does not exist")]
    UnknownNode {
        /// Group being built.
        group: String,
        /// Position of the instance in the group.
        instance_index: usize,
        /// The node id it names.
        child: u32,
    },
    /// An instance transform holds NaN or infinity, or is singular.
    #[error("instance {instance_index} of group '{group}' has a non-finite or singular transform")]
    BadTransform {
        /// Group being built.
        group: String,
        /// Position of the instance in the group.
        instance_index: usize,
    },
    /// Triangle instances overflow the 64-bit item id space.
    #[error("group '{0}' holds more than 2^64 triangle instances")]
    ItemOverflow(String),
    /// The camera cannot form a view.
    #[error("degenerate camera: {0}")]
    DegenerateCamera(String),
    /// The resolution is zero or larger than the engine allocates.
    #[error("bad resolution {width}x{height}: {reason}")]
    BadResolution {
        /// Requested width in pixels.
        width: u32,
        /// Requested height in pixels.
        height: u32,
        /// Why it is refused.
        reason: String,
    },
    /// Flattening would allocate more than the stated limit.
    #[error("scene has {triangle_count} triangle instances; flattening is limited to {limit}")]
    TooLargeToFlatten {
        /// Triangle instances in the scene.
        triangle_count: u64,
        /// The limit.
        limit: u64,
    },
}
