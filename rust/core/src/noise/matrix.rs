//! 3 × 3 colour matrices: product, inverse, and the camera matrix of an XYZ → camera
//! matrix with rows normalised so that white stays white (Brooks et al. 2019).
use super::camera::SRGB_TO_XYZ;

pub type Mat3 = [[f64; 3]; 3];

/// `a · b`.
pub fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    out
}

/// `m · v`.
pub fn apply(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

/// The inverse by cofactors (None when singular).
pub fn inverse(m: &Mat3) -> Option<Mat3> {
    let c = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
    };
    let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
    if !(det.is_finite() && det.abs() > 1e-12) {
        return None;
    }
    let mut out = [[0.0; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = c(j, i) / det;
        }
    }
    Some(out)
}

/// Linear sRGB → camera RGB from an XYZ → camera matrix: `xyz_to_cam · srgb_to_xyz`,
/// each row divided by its sum (white (1, 1, 1) maps to (1, 1, 1)).
pub fn cam_from_rgb(xyz_to_cam: &Mat3) -> Mat3 {
    let mut m = mul(xyz_to_cam, &SRGB_TO_XYZ);
    for row in &mut m {
        let s: f64 = row.iter().sum();
        for v in row.iter_mut() {
            *v /= s;
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::noise::camera::{BROOKS_XYZ_TO_CAM, ELD_CAMERAS};

    #[test]
    fn camera_matrices_keep_white_and_invert() {
        let mats = ELD_CAMERAS.iter().map(|c| c.xyz_to_cam);
        for x in mats.chain(BROOKS_XYZ_TO_CAM) {
            let m = cam_from_rgb(&x);
            let w = apply(&m, [1.0; 3]);
            assert!(w.iter().all(|v| (v - 1.0).abs() < 1e-12), "{w:?}");
            let inv = inverse(&m).expect("invertible");
            let id = mul(&inv, &m);
            for (i, row) in id.iter().enumerate() {
                for (j, v) in row.iter().enumerate() {
                    assert!((v - f64::from(u8::from(i == j))).abs() < 1e-12);
                }
            }
        }
    }
}
