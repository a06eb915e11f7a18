//! Cameras and views: where the eye is and how many pixels it sees.

use crate::error::{CoreError, Result};
use crate::geom::Frustum;
use glam::{Affine3A, Mat4, Vec2, Vec3, Vec4};
use serde::{Deserialize, Serialize};

/// Largest width or height a [`View`] accepts, in pixels.
pub const MAX_RESOLUTION: u32 = 16384;
/// Largest pixel count a [`View`] accepts (a 64 Mpixel frame is ~1.3 GB of buffers).
pub const MAX_PIXEL_COUNT: u64 = 1 << 26;

/// A perspective pinhole camera. Angles are degrees, distances world units.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Eye position, world space.
    pub eye: Vec3,
    /// Point looked at, world space.
    pub target: Vec3,
    /// Up direction, world space (need not be unit or orthogonal to the view direction).
    pub up: Vec3,
    /// Vertical field of view, degrees, in (0, 180).
    pub fov_y_deg: f32,
    /// Near plane distance, > 0.
    pub near: f32,
    /// Far plane distance, > near.
    pub far: f32,
}

impl Camera {
    /// A camera at `eye` looking at `target`, up `+y`, 60° vertical fov, near 0.1, far 1000.
    pub fn look_at(eye: Vec3, target: Vec3) -> Self {
        Self {
            eye,
            target,
            up: Vec3::Y,
            fov_y_deg: 60.0,
            near: 0.1,
            far: 1000.0,
        }
    }

    /// Checks that the camera forms a view.
    ///
    /// # Errors
    /// [`CoreError::DegenerateCamera`] for non-finite values, a fov outside (0°, 180°),
    /// `near <= 0`, `near >= far`, `eye == target`, `up` parallel to the view direction, or
    /// coordinates so large that `target - eye` overflows 32-bit floats.
    pub fn validate(&self) -> Result<()> {
        let bad = |why: &str| Err(CoreError::DegenerateCamera(why.to_string()));
        if !(self.eye.is_finite() && self.target.is_finite() && self.up.is_finite()) {
            return bad("eye, target or up is not finite");
        }
        if !(self.fov_y_deg > 0.0 && self.fov_y_deg < 180.0) {
            return bad(&format!("vertical fov {}° is not in (0°, 180°)", self.fov_y_deg));
        }
        if !(self.near > 0.0 && self.near.is_finite()) {
            return bad(&format!("near plane {} is not positive", self.near));
        }
        if !(self.far > self.near && self.far.is_finite()) {
            return bad(&format!(
                "far plane {} is not beyond near plane {}",
                self.far, self.near
            ));
        }
        let dir = self.target - self.eye;
        if !dir.is_finite() {
            return bad(
                "eye and target are too far apart: target - eye overflows 32-bit floats (coordinates too large)",
            );
        }
        // Compared by the largest component, whose square cannot overflow where the squared
        // length would (eye at 1e30 is far, not coincident).
        let largest = dir.abs().max_element();
        if largest * largest <= f32::MIN_POSITIVE {
            return bad("eye and target coincide");
        }
        if unit(dir).cross(unit(self.up)).length_squared() < 1e-10 {
            return bad("up is parallel to the view direction (or zero)");
        }
        Ok(())
    }

    /// Unit view direction.
    pub fn direction(&self) -> Vec3 {
        unit(self.target - self.eye)
    }
}

/// `v` scaled to unit length, or zero for a zero or non-finite `v`. Where its squared length
/// overflows (components beyond about 1.8e19) or underflows `f32`, scaled by its largest
/// component first; otherwise plain `normalize`, so that every ordinary camera keeps the
/// matrices, and the frames, it always had.
fn unit(v: Vec3) -> Vec3 {
    let squared = v.length_squared();
    if squared.is_finite() && squared >= f32::MIN_POSITIVE {
        return v.normalize();
    }
    let largest = v.abs().max_element();
    if !(largest > 0.0 && largest.is_finite()) {
        return Vec3::ZERO;
    }
    (v / largest).normalize_or_zero()
}

/// A validated camera with a resolution, and its matrices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    camera: Camera,
    width: u32,
    height: u32,
    view_from_world: Mat4,
    clip_from_view: Mat4,
    clip_from_world: Mat4,
    /// The pixels this view renders, columns `[x0, x1)` × rows `[y0, y1)` as
    /// `[x0, y0, x1, y1]`: the whole frame unless restricted ([`View::with_region`]).
    region: [u32; 4],
}

impl View {
    /// A view of `width × height` pixels.
    ///
    /// # Errors
    /// [`CoreError::DegenerateCamera`] (see [`Camera::validate`]) and
    /// [`CoreError::BadResolution`] for a zero side, a side over [`MAX_RESOLUTION`], or more
    /// than [`MAX_PIXEL_COUNT`] pixels.
    pub fn new(camera: Camera, width: u32, height: u32) -> Result<Self> {
        camera.validate()?;
        check_resolution(width, height)?;
        let view_from_world = look_at(camera.eye, camera.target, camera.up);
        let aspect = width as f32 / height as f32;
        let clip_from_view = reversed_z_infinite(camera.fov_y_deg.to_radians(), aspect, camera.near);
        let clip_from_world = clip_from_view * view_from_world;
        if !clip_from_world.is_finite() {
            return Err(CoreError::DegenerateCamera(
                "the view matrix overflows 32-bit floats (eye coordinates too large)".into(),
            ));
        }
        Ok(Self {
            camera,
            width,
            height,
            view_from_world,
            clip_from_view,
            clip_from_world,
            region: [0, 0, width, height],
        })
    }

    /// This view restricted to the pixels of columns `columns` and rows `rows` of its frame (a
    /// band of the screen, as sort-first rendering gives each thread): the same camera,
    /// matrices and resolution, so that every pixel of the region comes out as in the whole
    /// view; its [`View::frustum`] holds only what can reach the region, and the rasterizer
    /// writes no other pixel.
    ///
    /// # Errors
    /// [`CoreError::BadResolution`] for an empty range or one beyond the frame.
    pub fn with_region(&self, columns: std::ops::Range<u32>, rows: std::ops::Range<u32>) -> Result<Self> {
        if columns.start >= columns.end || columns.end > self.width || rows.start >= rows.end || rows.end > self.height
        {
            return Err(CoreError::BadResolution {
                width: self.width,
                height: self.height,
                reason: format!(
                    "columns {}..{} and rows {}..{} are not a region of it",
                    columns.start, columns.end, rows.start, rows.end
                ),
            });
        }
        Ok(Self {
            region: [columns.start, rows.start, columns.end, rows.end],
            ..*self
        })
    }

    /// The pixel columns this view renders (all of them unless restricted by
    /// [`View::with_region`]).
    pub fn columns(&self) -> std::ops::Range<u32> {
        self.region[0]..self.region[2]
    }

    /// The pixel rows this view renders (all of them unless restricted by
    /// [`View::with_region`]).
    pub fn rows(&self) -> std::ops::Range<u32> {
        self.region[1]..self.region[3]
    }

    /// Whether this view renders only a region of its frame ([`View::with_region`]).
    pub fn is_band(&self) -> bool {
        self.region != [0, 0, self.width, self.height]
    }

    /// The same camera at another resolution.
    ///
    /// # Errors
    /// As [`View::new`].
    pub fn with_resolution(&self, width: u32, height: u32) -> Result<Self> {
        Self::new(self.camera, width, height)
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }
    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }
    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }
    /// World to camera space (camera looks down `-z`).
    pub fn view_from_world(&self) -> Mat4 {
        self.view_from_world
    }
    /// Camera to clip space (reversed-Z, infinite far).
    pub fn clip_from_view(&self) -> Mat4 {
        self.clip_from_view
    }
    /// World to clip space.
    pub fn clip_from_world(&self) -> Mat4 {
        self.clip_from_world
    }

    /// `clip_from_world * world_from_object`: the one way every renderer forms this matrix.
    #[inline]
    pub fn clip_from_object(&self, world_from_object: &Affine3A) -> Mat4 {
        self.clip_from_world * Mat4::from(*world_from_object)
    }

    /// Depth (`z_ndc`) of the far plane: fragments with smaller depth are discarded.
    pub fn far_depth(&self) -> f32 {
        self.camera.near / self.camera.far
    }

    /// The culling frustum in object space, widened by two pixels on each side and by 0.1 %
    /// in depth, so that nothing it rejects could reach a pixel centre through the
    /// rasterizer's snapping and rounding.
    /// A region's ([`View::with_region`]) side planes bound its columns and rows instead,
    /// widened the same (a side that is the frame's own keeps the frame's plane).
    pub fn frustum(&self, world_from_object: &Affine3A) -> Frustum {
        let margin = Vec2::new(4.0 / self.width as f32, 4.0 / self.height as f32);
        let clip_from_object = self.clip_from_object(world_from_object);
        let frustum = Frustum::from_reversed_z(&clip_from_object, self.camera.far, margin, 1e-3);
        if !self.is_band() {
            return frustum;
        }
        // Screen column `sx` is `x_ndc = 2 sx / width - 1`, row `sy` is `y_ndc = 1 - 2 sy /
        // height`; the region two pixels wider on each side.
        let (w, h) = (self.width as f32, self.height as f32);
        let [x0, y0, x1, y1] = self.region;
        let left = (x0 > 0).then(|| 2.0 * (x0 as f32 - 2.0) / w - 1.0);
        let right = (x1 < self.width).then(|| 2.0 * (x1 as f32 + 2.0) / w - 1.0);
        let bottom = (y1 < self.height).then(|| 1.0 - 2.0 * (y1 as f32 + 2.0) / h);
        let top = (y0 > 0).then(|| 1.0 - 2.0 * (y0 as f32 - 2.0) / h);
        frustum.with_ranges(&clip_from_object, [left, right, bottom, top])
    }
}

/// Right-handed look-at: the camera looks down its `-z`, `+y` is up.
fn look_at(eye: Vec3, target: Vec3, up: Vec3) -> Mat4 {
    let f = unit(target - eye);
    let s = f.cross(unit(up)).normalize();
    let u = s.cross(f);
    Mat4::from_cols(
        Vec4::new(s.x, u.x, -f.x, 0.0),
        Vec4::new(s.y, u.y, -f.y, 0.0),
        Vec4::new(s.z, u.z, -f.z, 0.0),
        Vec4::new(-s.dot(eye), -u.dot(eye), f.dot(eye), 1.0),
    )
}

/// Reversed-Z perspective with an infinite far plane: `clip = (sx·x, sy·y, near, -z_view)`.
fn reversed_z_infinite(fov_y: f32, aspect: f32, near: f32) -> Mat4 {
    let sy = 1.0 / (0.5 * fov_y).tan();
    let sx = sy / aspect;
    Mat4::from_cols(
        Vec4::new(sx, 0.0, 0.0, 0.0),
        Vec4::new(0.0, sy, 0.0, 0.0),
        Vec4::new(0.0, 0.0, 0.0, -1.0),
        Vec4::new(0.0, 0.0, near, 0.0),
    )
}

/// Checks a resolution against the engine's limits.
///
/// # Errors
/// [`CoreError::BadResolution`] for a zero side, a side over [`MAX_RESOLUTION`], or more than
/// [`MAX_PIXEL_COUNT`] pixels.
pub fn check_resolution(width: u32, height: u32) -> Result<()> {
    let bad = |reason: String| Err(CoreError::BadResolution { width, height, reason });
    if width == 0 || height == 0 {
        return bad("zero width or height".into());
    }
    if width > MAX_RESOLUTION || height > MAX_RESOLUTION {
        return bad(format!("a side exceeds {MAX_RESOLUTION} pixels"));
    }
    if width as u64 * height as u64 > MAX_PIXEL_COUNT {
        return bad(format!("more than {MAX_PIXEL_COUNT} pixels"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> Camera {
        Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO)
    }

    #[test]
    fn degenerate_cameras_are_errors() {
        let mut c = cam();
        c.fov_y_deg = 0.0;
        assert!(View::new(c, 10, 10).is_err());
        let mut c = cam();
        c.near = 10.0;
        c.far = 1.0;
        assert!(View::new(c, 10, 10).is_err());
        let mut c = cam();
        c.target = c.eye;
        assert!(View::new(c, 10, 10).is_err());
        let mut c = cam();
        c.up = Vec3::Z;
        assert!(View::new(c, 10, 10).is_err());
        let mut c = cam();
        c.eye.x = f32::NAN;
        assert!(View::new(c, 10, 10).is_err());
    }

    #[test]
    fn huge_coordinates_work_or_say_they_are_too_large() {
        // |target - eye|^2 overflows f32, the direction does not: a valid, distant camera.
        let mut c = Camera::look_at(Vec3::new(1e30, 0.0, 0.0), Vec3::ZERO);
        c.far = 1e31;
        let v = View::new(c, 10, 10).expect("a camera 1e30 away with a far plane past it is valid");
        assert!(v.clip_from_world().is_finite());
        assert!((c.direction() - Vec3::NEG_X).length() < 1e-6);
        // A scene at ±1e20 framed from 2e20: the view works.
        let mut c = Camera::look_at(Vec3::new(0.0, 1e20, 2e20), Vec3::ZERO);
        c.near = 1e18;
        c.far = 1e21;
        View::new(c, 10, 10).expect("a scene at 1e20 framed from 2e20 is a valid view");
        // target - eye overflows: said so, not "coincide".
        let c = Camera::look_at(Vec3::new(3e38, 0.0, 0.0), Vec3::new(-3e38, 0.0, 0.0));
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("too large") && !e.contains("coincide"), "{e}");
        // A huge up vector is a direction like any other.
        let mut c = cam();
        c.up = Vec3::new(0.0, 1e30, 0.0);
        View::new(c, 10, 10).expect("a huge up vector is a valid direction");
        // The translation of the view matrix overflows: said so.
        let c = Camera::look_at(Vec3::splat(3e38), Vec3::new(3e38, 3e38, 2e38));
        let e = View::new(c, 10, 10).unwrap_err().to_string();
        assert!(e.contains("too large"), "{e}");
        // Coincident stays coincident.
        let c = Camera::look_at(Vec3::ONE, Vec3::ONE);
        assert!(c.validate().unwrap_err().to_string().contains("coincide"));
    }

    #[test]
    fn bad_resolutions_are_errors() {
        assert!(View::new(cam(), 0, 10).is_err());
        assert!(View::new(cam(), 10, 0).is_err());
        assert!(View::new(cam(), MAX_RESOLUTION + 1, 10).is_err());
        assert!(View::new(cam(), MAX_RESOLUTION, MAX_RESOLUTION).is_err());
        assert!(View::new(cam(), 1920, 1080).is_ok());
    }

    #[test]
    fn reversed_z_depth_is_near_over_distance() {
        let v = View::new(cam(), 100, 100).expect("a 100x100 view of the test camera");
        let p = v.clip_from_world() * glam::Vec4::new(0.0, 0.0, 0.0, 1.0);
        assert!((p.w - 5.0).abs() < 1e-5);
        assert!((p.z / p.w - 0.1 / 5.0).abs() < 1e-6);
    }

    #[test]
    fn frustum_culls_behind_and_beyond() {
        let v = View::new(cam(), 100, 100).expect("a 100x100 view of the test camera");
        let f = v.frustum(&Affine3A::IDENTITY);
        let unit = |c: Vec3| crate::Aabb::new(c - 0.5, c + 0.5);
        assert!(f.intersects_aabb(&unit(Vec3::ZERO)));
        assert!(!f.intersects_aabb(&unit(Vec3::new(0.0, 0.0, 10.0))));
        assert!(!f.intersects_aabb(&unit(Vec3::new(0.0, 0.0, -2000.0))));
        assert!(!f.intersects_aabb(&unit(Vec3::new(100.0, 0.0, 0.0))));
    }
}
