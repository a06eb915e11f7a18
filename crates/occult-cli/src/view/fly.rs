//! The flown camera: moves in the camera's own frame, turns about its up axis and its right
//! axis, orbits about the point it looks at. Field of view, near and far stay as given.

use occult_core::glam::Quat;
use occult_core::{Aabb, Camera, Vec3};

/// The camera being flown, with its speed.
#[derive(Clone, Debug)]
pub struct Fly {
    /// The camera.
    pub camera: Camera,
    /// World units per second.
    pub speed: f32,
}

/// The smallest angle kept between the view direction and up, degrees: closer, the view
/// would be degenerate.
const MIN_ANGLE_TO_UP_DEG: f32 = 2.0;

impl Fly {
    /// A camera flown at a tenth of the scene's diagonal per second.
    pub fn new(camera: Camera, bounds: &Aabb) -> Self {
        Self {
            camera,
            speed: default_speed(bounds),
        }
    }

    /// The unit view direction.
    pub fn forward(&self) -> Vec3 {
        (self.camera.target - self.camera.eye).normalize_or(Vec3::NEG_Z)
    }

    fn up(&self) -> Vec3 {
        self.camera.up.normalize_or(Vec3::Y)
    }

    fn right(&self) -> Vec3 {
        self.forward().cross(self.up()).normalize_or(Vec3::X)
    }

    /// Moves eye and target by `forward`, `right` and `up` world units along the camera's
    /// axes.
    pub fn step(&mut self, forward: f32, right: f32, up: f32) {
        let d = self.forward() * forward + self.right() * right + self.up() * up;
        if d.is_finite() {
            self.camera.eye += d;
            self.camera.target += d;
        }
    }

    /// Turns the view by `yaw_deg` to the right (about up) and `pitch_deg` upwards (about the
    /// right axis); a pitch that would bring the view within 2° of up or down is not applied.
    pub fn turn(&mut self, yaw_deg: f32, pitch_deg: f32) {
        let offset = self.camera.target - self.camera.eye;
        let distance = offset.length();
        if !(distance.is_finite() && distance > 0.0) {
            return;
        }
        let up = self.up();
        let mut direction = Quat::from_axis_angle(up, -yaw_deg.to_radians()) * (offset / distance);
        let right = direction.cross(up).normalize_or(Vec3::X);
        let pitched = Quat::from_axis_angle(right, pitch_deg.to_radians()) * direction;
        if pitched.angle_between(up).to_degrees() > MIN_ANGLE_TO_UP_DEG
            && pitched.angle_between(-up).to_degrees() > MIN_ANGLE_TO_UP_DEG
        {
            direction = pitched;
        }
        self.camera.target = self.camera.eye + direction.normalize() * distance;
    }

    /// Turns the eye about the target, `angle_deg` about up.
    pub fn orbit(&mut self, angle_deg: f32) {
        let rotation = Quat::from_axis_angle(self.up(), angle_deg.to_radians());
        self.camera.eye = self.camera.target + rotation * (self.camera.eye - self.camera.target);
    }

    /// Multiplies the speed by `1.25^steps` (a wheel's notches).
    pub fn scale_speed(&mut self, steps: f32) {
        let s = self.speed * 1.25f32.powf(steps);
        if s.is_finite() && s > 0.0 {
            self.speed = s;
        }
    }
}

/// A tenth of the scene's diagonal per second (one world unit for an empty scene).
pub fn default_speed(bounds: &Aabb) -> f32 {
    let diagonal = (bounds.max - bounds.min).length();
    if diagonal.is_finite() && diagonal > 0.0 {
        diagonal / 10.0
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fly() -> Fly {
        let camera = Camera::look_at(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO);
        Fly::new(camera, &Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0)))
    }

    #[test]
    fn steps_follow_the_view() {
        let mut f = fly();
        f.step(2.0, 1.0, 0.5);
        assert!(
            (f.camera.eye - Vec3::new(1.0, 0.5, 8.0)).length() < 1e-5,
            "{:?}",
            f.camera.eye
        );
        assert!((f.camera.target - Vec3::new(1.0, 0.5, -2.0)).length() < 1e-5);
    }

    #[test]
    fn turns_keep_distance_and_never_reach_up() {
        let mut f = fly();
        f.turn(90.0, 0.0);
        assert!((f.forward() - Vec3::X).length() < 1e-5, "{:?}", f.forward());
        for _ in 0..100 {
            f.turn(0.0, 10.0);
        }
        assert!(f.forward().angle_between(Vec3::Y).to_degrees() >= MIN_ANGLE_TO_UP_DEG - 1e-3);
        assert!(((f.camera.target - f.camera.eye).length() - 10.0).abs() < 1e-3);
        f.camera.validate().expect("a turned camera stays valid");
    }

    #[test]
    fn orbit_keeps_the_target() {
        let mut f = fly();
        f.orbit(90.0);
        assert_eq!(f.camera.target, Vec3::ZERO);
        assert!(
            (f.camera.eye - Vec3::new(10.0, 0.0, 0.0)).length() < 1e-4,
            "{:?}",
            f.camera.eye
        );
    }

    #[test]
    fn speed_follows_the_scene_and_the_wheel() {
        let mut f = fly();
        assert!((f.speed - 12f32.sqrt() / 10.0).abs() < 1e-6);
        let s = f.speed;
        f.scale_speed(1.0);
        assert!((f.speed - s * 1.25).abs() < 1e-6);
        f.scale_speed(f32::NAN);
        assert!((f.speed - s * 1.25).abs() < 1e-6);
        let empty = Aabb::new(Vec3::ZERO, Vec3::ZERO);
        assert_eq!(default_speed(&empty), 1.0);
    }
}
