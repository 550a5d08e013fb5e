//! The scene-dependent blur weight of the paper: flatness, depth range, orientation,
//! w_u = (F · R · O)^(1/3), and the level weight w_l ~ U[0.9, 1.1] · w_u · l.
//!
//! Guards (DESIGN §2: never a NaN or inf in an output):
//! - orientation O = max(d) / min(d) is capped at `orientation_max` by flooring min(d)
//!   at max(d) / orientation_max: a sheet or a single quad (min(d) → 0) would otherwise
//!   blur without bound;
//! - near n is floored at `near_floor` (object units; the object's largest side is 1)
//!   before R = f / n: a camera at the surface would make R → ∞;
//! - far is kept ≥ near, so F ≥ 0 and R ≥ 1;
//! - a degenerate box (max(d) → 0) is floored at 1e-9 so F stays finite (the loader
//!   rejects empty objects before this point).
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct Guards {
    pub orientation_max: f64,
    pub near_floor: f64,
}

impl Default for Guards {
    fn default() -> Self {
        Guards {
            orientation_max: 20.0,
            near_floor: 1e-3,
        }
    }
}

/// F, R, O and w_u of one view.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct SceneWeight {
    pub flatness: f64,
    pub depth_range: f64,
    pub orientation: f64,
    pub w_u: f64,
}

pub fn scene_weight(near: f64, far: f64, bbox_dims: [f64; 3], g: &Guards) -> SceneWeight {
    let finite_or = |v: f64, d: f64| if v.is_finite() { v } else { d };
    let dims = bbox_dims.map(|d| finite_or(d, 0.0).abs());
    let d_max = dims.iter().cloned().fold(0.0, f64::max).max(1e-9);
    let o_max = if g.orientation_max.is_finite() && g.orientation_max >= 1.0 {
        g.orientation_max
    } else {
        1.0
    };
    let d_min = dims
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min)
        .max(d_max / o_max);
    let n = finite_or(near, 0.0).max(g.near_floor.max(1e-12));
    let f = finite_or(far, n).max(n);
    let flatness = (f - n) / d_max;
    let depth_range = f / n;
    let orientation = d_max / d_min;
    SceneWeight {
        flatness,
        depth_range,
        orientation,
        w_u: libm::cbrt(flatness * depth_range * orientation),
    }
}

/// The interval w_l is drawn from for level `level`: [(1 − s) · w_u · l, (1 + s) · w_u · l].
pub fn level_interval(w_u: f64, level: u32, spread: f64) -> (f64, f64) {
    let c = w_u * level as f64;
    ((1.0 - spread) * c, (1.0 + spread) * c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn cube_example() {
        // unit cube seen from 2.8 along an axis: n = 2.3, f = 3.3
        let w = scene_weight(2.3, 3.3, [1.0, 1.0, 1.0], &Guards::default());
        assert!((w.flatness - 1.0).abs() < 1e-12);
        assert!((w.depth_range - 3.3 / 2.3).abs() < 1e-12);
        assert_eq!(w.orientation, 1.0);
        assert!((w.w_u - (3.3f64 / 2.3).cbrt()).abs() < 1e-12);
    }

    #[test]
    fn guards_keep_extremes_finite() {
        let g = Guards::default();
        // flat box: O capped
        let w = scene_weight(2.0, 2.5, [1.0, 1.0, 0.0], &g);
        assert_eq!(w.orientation, g.orientation_max);
        // camera at (or inside) the surface: n floored
        let w = scene_weight(0.0, 1.0, [1.0, 0.5, 0.5], &g);
        assert_eq!(w.depth_range, 1.0 / g.near_floor);
        let w = scene_weight(-0.3, 1.0, [1.0, 0.5, 0.5], &g);
        assert!(w.w_u.is_finite());
        // degenerate and non-finite inputs
        for w in [
            scene_weight(0.0, 0.0, [0.0, 0.0, 0.0], &g),
            scene_weight(f64::NAN, f64::INFINITY, [f64::NAN, 1.0, 0.0], &g),
            scene_weight(1.0, 0.5, [1.0, 1.0, 1.0], &g),
        ] {
            assert!(w.w_u.is_finite() && w.w_u >= 0.0, "{w:?}");
            assert!(w.depth_range >= 1.0 && w.flatness >= 0.0);
        }
    }

    proptest! {
        #[test]
        fn w_u_finite_and_monotone_in_far(
            near in 0.0f64..10.0, extent in 0.0f64..5.0,
            dx in 0.0f64..1.0, dy in 0.0f64..1.0, dz in 0.0f64..1.0,
        ) {
            let g = Guards::default();
            let a = scene_weight(near, near + extent, [dx, dy, dz], &g);
            let b = scene_weight(near, near + extent + 0.1, [dx, dy, dz], &g);
            prop_assert!(a.w_u.is_finite() && a.w_u >= 0.0);
            prop_assert!(a.orientation >= 1.0 && a.orientation <= g.orientation_max + 1e-9);
            prop_assert!(b.w_u >= a.w_u);
        }
    }
}
