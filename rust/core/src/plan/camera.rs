//! Cameras on a sphere around the object: position from (r, φ, θ), look-at, depth range.
//!
//! World is Z-up; φ is the polar angle from +Z, θ the azimuth from +X towards +Y.
//! Camera-to-world matrices are OpenGL / Blender (columns right, up, backwards, position).
use crate::rng::Stream;
use glam::{DMat4, DVec3, DVec4};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Polar angles are kept this far (degrees) from the poles, where the look-at with
/// up = +Z degenerates.
pub const POLE_MARGIN_DEG: f64 = 0.5;

/// A point on the sphere of radius `r` (φ, θ in degrees); φ is clamped off the poles.
pub fn position(r: f64, phi_deg: f64, theta_deg: f64) -> DVec3 {
    let phi = clamp_polar(phi_deg).to_radians();
    let theta = theta_deg.to_radians();
    DVec3::new(
        r * libm::sin(phi) * libm::cos(theta),
        r * libm::sin(phi) * libm::sin(theta),
        r * libm::cos(phi),
    )
}

/// The polar-angle guard: φ in [margin, 180 − margin].
pub fn clamp_polar(phi_deg: f64) -> f64 {
    phi_deg.clamp(POLE_MARGIN_DEG, 180.0 - POLE_MARGIN_DEG)
}

/// OpenGL camera-to-world for a camera at `eye` looking at `target` with world up +Z.
/// At (or numerically near) a pole the up hint falls back to +Y so the basis stays
/// orthonormal instead of becoming NaN.
pub fn look_at(eye: DVec3, target: DVec3) -> DMat4 {
    let fwd = (target - eye).normalize_or(DVec3::NEG_Z);
    let mut right = fwd.cross(DVec3::Z);
    if right.length_squared() < 1e-18 {
        right = fwd.cross(DVec3::Y);
    }
    let right = right.normalize();
    let up = right.cross(fwd);
    DMat4::from_cols(
        right.extend(0.0),
        up.extend(0.0),
        (-fwd).extend(0.0),
        DVec4::new(eye.x, eye.y, eye.z, 1.0),
    )
}

/// Camera looking at the origin from spherical coordinates.
pub fn orbit_c2w(r: f64, phi_deg: f64, theta_deg: f64) -> DMat4 {
    look_at(position(r, phi_deg, theta_deg), DVec3::ZERO)
}

/// Near and far: the smallest and largest camera-space depth (along the viewing
/// direction) of `points`. Empty input gives (0, 0).
pub fn depth_range(c2w: &DMat4, points: &[[f32; 3]]) -> (f64, f64) {
    let eye = c2w.w_axis.truncate();
    let fwd = -c2w.z_axis.truncate();
    let (near, far) = points
        .par_iter()
        .with_min_len(4096)
        .map(|p| (DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64) - eye).dot(fwd))
        .fold(
            || (f64::INFINITY, f64::NEG_INFINITY),
            |(lo, hi), d| (lo.min(d), hi.max(d)),
        )
        .reduce(
            || (f64::INFINITY, f64::NEG_INFINITY),
            |a, b| (a.0.min(b.0), a.1.max(b.1)),
        );
    if near.is_finite() {
        (near, far)
    } else {
        (0.0, 0.0)
    }
}

/// Focal length in pixels for a square image of `size` px and field of view `fov_deg`.
pub fn focal_px(size: u32, fov_deg: f64) -> f64 {
    0.5 * size as f64 / libm::tan(0.5 * fov_deg.to_radians())
}

/// The trajectory δ of a view (DESIGN §2), a displacement in the orbit's own coordinates
/// (r, φ, θ): the view's camera moves from p along it over the exposure.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct Trajectory {
    /// Δr in percent of r.
    pub dr: f64,
    pub dphi_deg: f64,
    pub dtheta_deg: f64,
}

impl Trajectory {
    /// δ of one view: each component's magnitude uniform in [δ0 / 2, δ0], its sign
    /// random, so every view moves along all three coordinates.
    pub fn draw(delta0: f64, s: &mut Stream) -> Trajectory {
        let mut component = || {
            let mag = s.uniform_in(delta0 / 2.0, delta0);
            mag * s.sign()
        };
        Trajectory {
            dr: component(),
            dphi_deg: component(),
            dtheta_deg: component(),
        }
    }
}

/// Radius of the sphere around the box (centred at the origin).
pub fn bounding_radius(bbox_dims: [f64; 3]) -> f64 {
    0.5 * DVec3::from_array(bbox_dims).length()
}

/// A row-major copy of a matrix (meta.json and the worker take rows).
pub(crate) fn rows(m: &DMat4) -> [[f64; 4]; 4] {
    m.transpose().to_cols_array_2d()
}

/// The corners of a box of dimensions `d` centred at the origin.
pub(crate) fn corners(d: [f64; 3]) -> [DVec3; 8] {
    std::array::from_fn(|i| {
        DVec3::new(
            if i & 1 == 0 { -0.5 } else { 0.5 } * d[0],
            if i & 2 == 0 { -0.5 } else { 0.5 } * d[1],
            if i & 4 == 0 { -0.5 } else { 0.5 } * d[2],
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn looks_at_origin_with_z_up() {
        for &(phi, theta) in &[
            (60.0, 0.0),
            (52.5, 97.0),
            (67.5, 275.0),
            (0.0, 0.0),
            (180.0, 33.0),
        ] {
            let m = orbit_c2w(3.0, phi, theta);
            let eye = m.w_axis.truncate();
            let back = m.z_axis.truncate();
            // forward (−back) points at the origin
            assert!((-back).dot(-eye.normalize()) > 1.0 - 1e-12, "{phi} {theta}");
            // orthonormal, right-handed
            let r3 = glam::DMat3::from_mat4(m);
            assert!((r3.determinant() - 1.0).abs() < 1e-12);
            assert!((r3.transpose() * r3).abs_diff_eq(glam::DMat3::IDENTITY, 1e-12));
            // camera up has a non-negative world-Z component: images are not upside down
            assert!(m.y_axis.z >= -1e-12);
            assert!(m.to_cols_array().iter().all(|v| v.is_finite()));
        }
    }

    #[test]
    fn exact_pole_is_finite() {
        let m = look_at(DVec3::new(0.0, 0.0, 2.0), DVec3::ZERO);
        assert!(m.to_cols_array().iter().all(|v| v.is_finite()));
        assert!((glam::DMat3::from_mat4(m).determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn depth_range_of_a_cube() {
        let m = orbit_c2w(3.0, 90.0, 0.0); // on +X, looking along −X
        let pts: Vec<[f32; 3]> = (0..8)
            .map(|i| {
                [
                    if i & 1 == 0 { -0.5 } else { 0.5 },
                    if i & 2 == 0 { -0.5 } else { 0.5 },
                    if i & 4 == 0 { -0.5 } else { 0.5 },
                ]
            })
            .collect();
        let (n, f) = depth_range(&m, &pts);
        assert!((n - 2.5).abs() < 1e-9 && (f - 3.5).abs() < 1e-9, "{n} {f}");
        assert_eq!(depth_range(&m, &[]), (0.0, 0.0));
    }

    #[test]
    fn focal_of_90_degrees_is_half_width() {
        assert!((focal_px(512, 90.0) - 256.0).abs() < 1e-9);
    }
}
