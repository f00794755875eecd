//! The pinhole camera shared by the rasteriser and the path tracer.
//!
//! Pixel `(x, y)` covers `[x, x+1) × [y, y+1)` in continuous image coordinates, row 0 at the
//! top; its centre is `(x + 0.5, y + 0.5)`. The vertical field of view spans the image height,
//! the horizontal one follows from the aspect ratio (square pixels).

use glam::Vec3;
use hirad_core::geom::Aabb;
use hirad_core::{Error, Result};
use hirad_scene::Camera;
use serde::{Deserialize, Serialize};

/// A validated pinhole view: eye, target, up, vertical field of view and image size.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraView {
    /// Eye position (scene units).
    pub eye: Vec3,
    /// Point looked at.
    pub target: Vec3,
    /// Up direction (need not be unit or orthogonal to the view).
    pub up: Vec3,
    /// Vertical field of view, degrees, in (0, 180).
    pub fov_deg: f32,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

/// Command-line overrides of a scene camera (`--eye --target --up --fov --size`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CameraOverrides {
    /// Eye position.
    pub eye: Option<Vec3>,
    /// Point looked at.
    pub target: Option<Vec3>,
    /// Camera up vector.
    pub up: Option<Vec3>,
    /// Vertical field of view, degrees.
    pub fov_deg: Option<f32>,
    /// Image size (width, height), pixels.
    pub size: Option<(u32, u32)>,
}

/// Orthonormal camera frame and projection constants derived from a [`CameraView`].
#[derive(Clone, Copy, Debug)]
pub struct CameraFrame {
    /// Eye position (scene units).
    pub eye: Vec3,
    /// Unit viewing direction.
    pub forward: Vec3,
    /// Unit vector to the right of the image.
    pub right: Vec3,
    /// Unit vector to the top of the image.
    pub up: Vec3,
    /// tan(fov/2): half image height at distance 1.
    pub tan_half_y: f32,
    /// tan(fov/2) · width/height: half image width at distance 1.
    pub tan_half_x: f32,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

impl CameraView {
    /// The view of a scene camera.
    pub fn from_camera(c: &Camera) -> CameraView {
        CameraView {
            eye: c.eye,
            target: c.target,
            up: c.up,
            fov_deg: c.fov_deg,
            width: c.width,
            height: c.height,
        }
    }

    /// A scene camera with command-line overrides applied, validated.
    pub fn with_overrides(c: &Camera, o: &CameraOverrides) -> Result<CameraView> {
        let mut v = CameraView::from_camera(c);
        v.apply(o);
        v.validate()?;
        Ok(v)
    }

    /// Apply overrides in place.
    pub fn apply(&mut self, o: &CameraOverrides) {
        if let Some(e) = o.eye {
            self.eye = e;
        }
        if let Some(t) = o.target {
            self.target = t;
        }
        if let Some(u) = o.up {
            self.up = u;
        }
        if let Some(f) = o.fov_deg {
            self.fov_deg = f;
        }
        if let Some((w, h)) = o.size {
            self.width = w;
            self.height = h;
        }
    }

    /// A view of a bounding box from a diagonal direction slightly above it (the box fits in
    /// the field of view), for meshes that carry no camera.
    pub fn looking_at_box(bbox: &Aabb, up: Vec3, width: u32, height: u32) -> CameraView {
        let up = up.normalize_or(Vec3::Y);
        let c = bbox.center();
        let r = (bbox.extent().length() * 0.5).max(1e-6);
        // A horizontal direction not parallel to `up`.
        let a = if up.x.abs() < 0.9 { Vec3::X } else { Vec3::Z };
        let side = (a + 1.4 * up.cross(a)).normalize();
        let fov_deg: f32 = 45.0;
        let dist = r / (0.5 * fov_deg.to_radians()).sin();
        let eye = c + (side + 0.5 * up).normalize() * dist;
        CameraView {
            eye,
            target: c,
            up,
            fov_deg,
            width,
            height,
        }
    }

    /// Check that the view is usable: finite vectors, eye ≠ target, up not parallel to the
    /// viewing direction, fov in (0, 180), non-zero size of at most 65536 × 65536.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::Config(format!("camera: {m}")));
        if !(self.eye.is_finite() && self.target.is_finite() && self.up.is_finite()) {
            return bad("eye, target and up must be finite".into());
        }
        let f = self.target - self.eye;
        if f.length() <= 0.0 {
            return bad("eye and target coincide".into());
        }
        if self.up.length() <= 0.0 || f.normalize().cross(self.up.normalize()).length() < 1e-6 {
            return bad(format!(
                "up {} is zero or parallel to the viewing direction",
                self.up
            ));
        }
        if !(self.fov_deg > 0.0 && self.fov_deg < 180.0) {
            return bad(format!("fov {} must be in (0, 180) degrees", self.fov_deg));
        }
        if self.width == 0 || self.height == 0 || self.width > 65536 || self.height > 65536 {
            return bad(format!(
                "image size {}x{} must be between 1x1 and 65536x65536",
                self.width, self.height
            ));
        }
        Ok(())
    }

    /// The camera frame (call [`CameraView::validate`] first).
    pub fn frame(&self) -> CameraFrame {
        let forward = (self.target - self.eye).normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        let tan_half_y = (0.5 * self.fov_deg.to_radians()).tan();
        CameraFrame {
            eye: self.eye,
            forward,
            right,
            up,
            tan_half_y,
            tan_half_x: tan_half_y * self.width as f32 / self.height as f32,
            width: self.width,
            height: self.height,
        }
    }
}

impl CameraFrame {
    /// Unnormalised direction of the ray through continuous image position `(sx, sy)`
    /// (pixels, row 0 at the top); its component along `forward` is 1.
    #[inline]
    pub fn direction(&self, sx: f32, sy: f32) -> Vec3 {
        let nx = (2.0 * sx / self.width as f32 - 1.0) * self.tan_half_x;
        let ny = (1.0 - 2.0 * sy / self.height as f32) * self.tan_half_y;
        self.forward + nx * self.right + ny * self.up
    }

    /// Clip coordinates `(X, Y, W)` of a point: `X/W` and `Y/W` are in [-1, 1] on the image,
    /// `W` is the distance along the viewing direction.
    #[inline]
    pub fn to_clip(&self, p: Vec3) -> Vec3 {
        let d = p - self.eye;
        Vec3::new(
            d.dot(self.right) / self.tan_half_x,
            d.dot(self.up) / self.tan_half_y,
            d.dot(self.forward),
        )
    }

    /// Continuous image position of a point in front of the camera (`W > 0`).
    #[inline]
    pub fn project(&self, p: Vec3) -> Option<(f32, f32)> {
        let c = self.to_clip(p);
        (c.z > 0.0).then(|| {
            (
                (c.x / c.z + 1.0) * 0.5 * self.width as f32,
                (1.0 - c.y / c.z) * 0.5 * self.height as f32,
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view() -> CameraView {
        CameraView {
            eye: Vec3::new(0.0, 0.0, 5.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            fov_deg: 90.0,
            width: 200,
            height: 100,
        }
    }

    #[test]
    fn ray_and_projection_agree() {
        let f = view().frame();
        for &(sx, sy) in &[
            (0.5f32, 0.5f32),
            (100.0, 50.0),
            (173.25, 12.5),
            (199.5, 99.5),
        ] {
            let p = f.eye + f.direction(sx, sy) * 3.7;
            let (x, y) = f.project(p).unwrap();
            assert!((x - sx).abs() < 1e-3 && (y - sy).abs() < 1e-3, "{x} {y}");
        }
        // Centre of the image looks at the target; top edge at 45° up (fov 90°).
        let d = f.direction(100.0, 0.0);
        assert!((d.normalize().dot(Vec3::Y) - 45f32.to_radians().sin()).abs() < 1e-6);
        assert!((f.direction(100.0, 50.0).normalize() - Vec3::NEG_Z).length() < 1e-6);
        // Right of the image is +X when looking down -Z with +Y up.
        assert!(f.project(Vec3::new(1.0, 0.0, 0.0)).unwrap().0 > 100.0);
    }

    #[test]
    fn validation() {
        assert!(view().validate().is_ok());
        let mut v = view();
        v.up = Vec3::Z;
        assert!(v.validate().is_err());
        let mut v = view();
        v.fov_deg = 180.0;
        assert!(v.validate().is_err());
        let mut v = view();
        v.width = 0;
        assert!(v.validate().is_err());
        let mut v = view();
        v.target = v.eye;
        assert!(v.validate().is_err());
    }

    #[test]
    fn box_view_sees_the_box() {
        let b = Aabb::new(Vec3::new(-1.0, 0.0, -2.0), Vec3::new(3.0, 1.0, 0.5));
        for up in [Vec3::Y, Vec3::Z] {
            let v = CameraView::looking_at_box(&b, up, 64, 64);
            v.validate().unwrap();
            let f = v.frame();
            for i in 0..8 {
                let p = Vec3::new(
                    if i & 1 == 0 { b.min.x } else { b.max.x },
                    if i & 2 == 0 { b.min.y } else { b.max.y },
                    if i & 4 == 0 { b.min.z } else { b.max.z },
                );
                let (x, y) = f.project(p).unwrap();
                assert!((0.0..=64.0).contains(&x) && (0.0..=64.0).contains(&y));
            }
        }
    }
}
