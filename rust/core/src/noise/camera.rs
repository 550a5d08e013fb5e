//! Published camera data the raw noise models use (issue 61), as constants.
//!
//! ELD (Wei et al., CVPR 2020 / TPAMI 2021) calibrations: the five files
//! `camera_params/release/<Camera>_params.npy` of github.com/Vandermode/ELD (MIT) at
//! commit 53d5408dec3a33e5ca304bb49682d7b6b6dc79c2, `Profile-1` of each, copied as
//! numbers (Python's repr of the float64 values): `Kmin`, `Kmax` (system gain K, DN per
//! electron, over the calibrated ISOs), `G_scale` (Tukey-lambda read-noise scale),
//! `R_scale` (row-noise σ), each a fit `ln σ = slope · ln K + bias` with residual spread
//! `sigma`, and `G_shape` (the Tukey λ of each calibrated capture, in the file's order).
//! The files' `g_scale` (Gaussian baseline) and `color_bias` (per-channel black-level
//! offsets) are not used.
//!
//! Black and white levels (14-bit DN) and colour matrices are not in ELD's release:
//! - `xyz_to_cam` is Adobe's D65 ColorMatrix as dcraw/LibRaw's `adobe_coeff` table
//!   holds it (÷ 10000). Sony ILCE-7S ("also ILCE-7SM2"), Canon EOS 70D and EOS 700D
//!   were checked against a copy of dcraw's table; Nikon D850 and Canon EOS 5D Mark IV
//!   are recalled from LibRaw's table and were not checked against a copy here
//!   (approximate).
//! - `white`: Canon EOS 70D 0x3bc7 = 15303 and EOS 700D 0x3c00 = 15360 are dcraw's
//!   table maxima (checked); Sony A7S2 16383 with black 512 are the values SID/ELD's
//!   Sony raws carry; Nikon D850 (black 400, white 15520), Canon 70D/700D black 2048
//!   and Canon 5D Mark IV (black 512, white 16383) are typical 14-bit values recalled,
//!   not read from a file (approximate).

/// A log-linear fit of a noise scale against the system gain: `ln σ = slope · ln K + bias`,
/// residual standard deviation `sigma` (in ln σ).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fit {
    pub slope: f64,
    pub bias: f64,
    pub sigma: f64,
}

impl Fit {
    /// The fit's mean scale at system gain `k` (the residual spread is not drawn).
    pub fn at(&self, k: f64) -> f64 {
        libm::exp(self.slope * libm::log(k) + self.bias)
    }
}

/// One camera of ELD's release with the levels and matrix it needs to make raw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EldCamera {
    pub name: &'static str,
    pub k_min: f64,
    pub k_max: f64,
    /// `G_scale`: the Tukey-lambda read noise's scale (DN).
    pub read_scale: Fit,
    /// `R_scale`: the row noise's σ (DN).
    pub row_scale: Fit,
    /// `G_shape`: Tukey λ per calibrated capture, lowest ISO first.
    pub shape: &'static [f64],
    pub black: f64,
    pub white: f64,
    /// Adobe D65 colour matrix, XYZ → camera RGB.
    pub xyz_to_cam: [[f64; 3]; 3],
}

/// The bit depth of every camera here (14-bit raw).
pub const ELD_BITS: u32 = 14;

/// The ELD source named in noise.json.
pub const ELD_SOURCE: &str = "Wei et al. 2020/2021 (ELD), github.com/Vandermode/ELD \
    camera_params/release/<camera>_params.npy Profile-1 @ 53d5408dec3a33e5ca304bb49682d7b6b6dc79c2";

/// The levels' and matrices' source named in noise.json.
pub const LEVELS_SOURCE: &str = "colour matrix: Adobe D65 ColorMatrix from dcraw/LibRaw \
    adobe_coeff (Nikon D850, Canon 5D Mark IV recalled, approximate); black/white: dcraw \
    maxima (Canon 70D, 700D), SID/ELD Sony raws (A7S2), else typical 14-bit values \
    (approximate)";

/// The five cameras of ELD's release.
pub const ELD_CAMERAS: [EldCamera; 5] = [
    EldCamera {
        name: "SonyA7S2",
        k_min: 0.09391607086816033,
        k_max: 6.010628535562261,
        read_scale: Fit {
            slope: 0.46210495986526035,
            bias: 0.5657147358616816,
            sigma: 0.2633712220097871,
        },
        row_scale: Fit {
            slope: 0.5275360468633209,
            bias: -0.5917002648887661,
            sigma: 0.29428813016491145,
        },
        shape: &[
            0.11428571428571421,
            0.12857142857142856,
            0.05714285714285716,
            0.042857142857142816,
            0.0,
            0.0,
            -0.04285714285714287,
            -0.05714285714285716,
            -0.08571428571428574,
            -0.08571428571428574,
            -0.08571428571428574,
            -0.08571428571428574,
            -0.11428571428571432,
            -0.11428571428571432,
            -0.14285714285714285,
            -0.12857142857142856,
            -0.14285714285714285,
            -0.14285714285714285,
        ],
        black: 512.0,
        white: 16383.0,
        xyz_to_cam: [
            [0.5838, -0.143, -0.0246],
            [-0.3497, 1.1477, 0.2297],
            [-0.0748, 0.1885, 0.5778],
        ],
    },
    EldCamera {
        name: "NikonD850",
        k_min: 0.4150393264348262,
        k_max: 26.562516891828878,
        read_scale: Fit {
            slope: 0.4773896839219417,
            bias: -0.09044499670414502,
            sigma: 0.23920060971003035,
        },
        row_scale: Fit {
            slope: 0.44829219631519307,
            bias: -1.7977103277112132,
            sigma: 0.2321799439489326,
        },
        shape: &[
            -0.11428571428571432,
            -0.11428571428571432,
            -0.2,
            -0.2,
            -0.2142857142857143,
            -0.2142857142857143,
            -0.2285714285714286,
            -0.2285714285714286,
            -0.24285714285714288,
            -0.24285714285714288,
            -0.17142857142857143,
            -0.17142857142857143,
            -0.14285714285714285,
            -0.14285714285714285,
            -0.10000000000000003,
            -0.10000000000000003,
        ],
        black: 400.0,
        white: 15520.0,
        xyz_to_cam: [
            [1.0405, -0.3755, -0.127],
            [-0.5461, 1.3787, 0.1793],
            [-0.104, 0.2015, 0.6785],
        ],
    },
    EldCamera {
        name: "CanonEOS70D",
        k_min: 0.40749699481911256,
        k_max: 26.079807668423204,
        read_scale: Fit {
            slope: 0.4868061424083776,
            bias: 1.4642678570994598,
            sigma: 0.3820056048326114,
        },
        row_scale: Fit {
            slope: 0.7292220505388829,
            bias: -0.9370565150367796,
            sigma: 0.2502155842967251,
        },
        shape: &[
            0.1428571428571428,
            0.1428571428571428,
            0.11428571428571421,
            0.11428571428571421,
            0.02857142857142858,
            0.02857142857142858,
            -0.10000000000000003,
            -0.08571428571428574,
            -0.17142857142857143,
            -0.17142857142857143,
            -0.15714285714285714,
            -0.15714285714285714,
            -0.08571428571428574,
            -0.08571428571428574,
            -0.02857142857142858,
            -0.02857142857142858,
        ],
        black: 2048.0,
        white: 15303.0,
        xyz_to_cam: [
            [0.7034, -0.0804, -0.1014],
            [-0.442, 1.2564, 0.2058],
            [-0.0851, 0.1994, 0.5758],
        ],
    },
    EldCamera {
        name: "CanonEOS700D",
        k_min: 0.44762889266510675,
        k_max: 28.648249130566832,
        read_scale: Fit {
            slope: 0.5982361749821256,
            bias: 1.5370438794284738,
            sigma: 0.3888189465002228,
        },
        row_scale: Fit {
            slope: 0.6220587550621577,
            bias: -0.7756471105987757,
            sigma: 0.24848083434051538,
        },
        shape: &[
            0.12857142857142856,
            0.12857142857142856,
            0.09999999999999998,
            0.09999999999999998,
            0.014285714285714235,
            0.014285714285714235,
            -0.08571428571428574,
            -0.10000000000000003,
            -0.14285714285714285,
            -0.15714285714285714,
            -0.12857142857142856,
            -0.12857142857142856,
            -0.02857142857142858,
            -0.02857142857142858,
            0.014285714285714235,
            0.014285714285714235,
        ],
        black: 2048.0,
        white: 15360.0,
        xyz_to_cam: [
            [0.6602, -0.0841, -0.0939],
            [-0.4472, 1.2458, 0.2247],
            [-0.0975, 0.2039, 0.6148],
        ],
    },
    EldCamera {
        name: "CanonEOS5D4",
        k_min: 0.2181895124454343,
        k_max: 13.964128796507795,
        read_scale: Fit {
            slope: 0.6558756156508007,
            bias: 1.09268679594838,
            sigma: 0.28604721742277756,
        },
        row_scale: Fit {
            slope: 0.4712797750747537,
            bias: -0.8078958947116487,
            sigma: 0.2436176299944695,
        },
        shape: &[
            0.15714285714285714,
            0.1428571428571428,
            0.08571428571428574,
            0.08571428571428574,
            0.2,
            0.2,
            0.09999999999999998,
            0.08571428571428574,
            0.05714285714285716,
            0.0714285714285714,
            0.02857142857142858,
            0.02857142857142858,
            0.014285714285714235,
            0.02857142857142858,
            0.08571428571428574,
            0.0714285714285714,
            0.11428571428571421,
            0.11428571428571421,
        ],
        black: 512.0,
        white: 16383.0,
        xyz_to_cam: [
            [0.6446, -0.0366, -0.0864],
            [-0.4436, 1.2204, 0.2513],
            [-0.0952, 0.2496, 0.6348],
        ],
    },
];

/// The ELD camera of a name (case-insensitive), if any.
pub fn eld_camera(name: &str) -> Option<&'static EldCamera> {
    ELD_CAMERAS
        .iter()
        .find(|c| c.name.eq_ignore_ascii_case(name))
}

/// Brooks et al. 2019 (Unprocessing Images for Learned Raw Denoising, `unprocess.py`
/// of google-research/unprocessing): the XYZ → camera matrices of their four cameras,
/// between which each scene's colour matrix is drawn. From the paper's published code,
/// recalled; the second is dcraw's Sony ILCE-7R matrix (checked).
pub const BROOKS_XYZ_TO_CAM: [[[f64; 3]; 3]; 4] = [
    [
        [1.0234, -0.2969, -0.2266],
        [-0.5625, 1.6328, -0.0469],
        [-0.0703, 0.2188, 0.6406],
    ],
    [
        [0.4913, -0.0541, -0.0202],
        [-0.613, 1.3513, 0.2906],
        [-0.1564, 0.2151, 0.7183],
    ],
    [
        [0.838, -0.263, -0.0639],
        [-0.2887, 1.0725, 0.2496],
        [-0.0627, 0.1427, 0.5438],
    ],
    [
        [0.6596, -0.2079, -0.0562],
        [-0.4782, 1.3016, 0.1933],
        [-0.097, 0.1581, 0.5181],
    ],
];

/// Linear sRGB (D65) → XYZ (IEC 61966-2-1), as Brooks et al. use it.
pub const SRGB_TO_XYZ: [[f64; 3]; 3] = [
    [0.4124564, 0.3575761, 0.1804375],
    [0.2126729, 0.7151522, 0.0721750],
    [0.0193339, 0.1191920, 0.9503041],
];
