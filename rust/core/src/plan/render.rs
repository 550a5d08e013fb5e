//! One render as the plan gives it to the Blender worker: the camera, its seed and
//! samples, the EXR it writes, the image it is accumulated into, and the fields a
//! degradation adds (a motion blur render's camera path, a defocus render's lens).
use super::region::Region;
use crate::plan::kind::ImageKind;
use serde::Serialize;

/// The camera path of one Cycles motion blur render.
#[derive(Clone, Debug, Serialize, PartialEq, schemars::JsonSchema)]
pub struct Motion {
    pub steps: u32,
    /// OpenGL camera-to-world matrices (row-major) at t_k = k / 2^steps.
    pub keys: Vec<[[f64; 4]; 4]>,
}

/// The thin lens of a defocus render ([`super::defocus`]).
#[derive(Clone, Copy, Debug, Serialize, PartialEq, schemars::JsonSchema)]
pub struct Dof {
    /// Distance of the plane in focus along the viewing axis (world units).
    pub focus_distance: f64,
    /// Radius of the lens aperture (world units).
    pub aperture_radius: f64,
}

/// One render: the camera, its Cycles seed and samples, the EXR it writes, and the
/// view and image it is accumulated into.
#[derive(Clone, Debug, Serialize, PartialEq, schemars::JsonSchema)]
pub struct Render {
    pub view: usize,
    /// The image's level directory: its `kind`'s ([`ImageKind::dir`]).
    pub level: String,
    pub kind: ImageKind,
    /// The render phase the builder renders it in, phases in ascending order (the
    /// sharp images first, whose QA gates the rest): its kind's ([`ImageKind::phase`]).
    pub phase: u32,
    /// OpenGL camera-to-world, row-major.
    pub c2w: [[f64; 4]; 4],
    pub seed: u32,
    /// Cycles samples of this render; None: the caller's (the sharp render's own count).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub samples: Option<u32>,
    /// Under sample subsets (issue 15): this render takes the samples [sample_offset,
    /// sample_offset + samples) of a Cycles sequence of `sample_sequence` samples.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sample_offset: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sample_sequence: Option<u32>,
    pub out: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motion: Option<Motion>,
    /// The pixels this render traces: those of its render call, which contain every
    /// pixel that can see the object ([`super::region`]); None: the whole image.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub region: Option<Region>,
    /// Which Blender render call renders it: consecutive renders with one `call` are one
    /// animation job ([`super::region::render_calls`]); None: a call of its own.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub call: Option<usize>,
    /// Under a render target ([`super::target`]): which of the image's two independent
    /// halves this render adds to (0 or 1); None: the image has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub half: Option<u32>,
    /// A defocus render's lens (issue 35); None: a pinhole camera.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dof: Option<Dof>,
    /// A rolling shutter's band ([`crate::plan::kinds::rolling`]): this render exposes
    /// only some rows of its image, one of the bands that tile it; None: every row.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub band: Option<Band>,
    /// A motion blur render through Cycles' rolling shutter: each row exposed at its own
    /// time along the keys, top row first; None: every row at once.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rolling_shutter: Option<bool>,
}

/// The rows a render exposes of its image: `rows` [top, bottom), one of `of` bands that
/// tile the image's rows once.
#[derive(Clone, Copy, Debug, Serialize, PartialEq, schemars::JsonSchema)]
pub struct Band {
    pub rows: [u32; 2],
    pub of: u32,
}

impl Render {
    /// A pinhole render of one still image at `c2w` with the caller's samples: whole
    /// image, a call of its own, no halves, no lens, until the plan says otherwise.
    pub(crate) fn still(
        view: usize,
        kind: ImageKind,
        c2w: [[f64; 4]; 4],
        seed: u32,
        out: String,
    ) -> Render {
        Render {
            view,
            level: kind.dir(),
            kind,
            phase: kind.phase(),
            c2w,
            seed,
            samples: None,
            sample_offset: None,
            sample_sequence: None,
            out,
            motion: None,
            region: None,
            call: None,
            half: None,
            dof: None,
            band: None,
            rolling_shutter: None,
        }
    }

    /// A render that is a whole-image call of its own: a motion blur render, or a
    /// defocus render, whose blur spills past the object's pinhole footprint.
    pub(crate) fn whole(&self) -> bool {
        self.motion.is_some() || self.dof.is_some()
    }

    /// The share of a whole image one frame of this render's image is in its mean's
    /// weight: 1, or 1/n for each of n bands that tile the image (each pixel gets one).
    pub fn share(&self) -> f64 {
        self.band.map_or(1.0, |b| 1.0 / f64::from(b.of.max(1)))
    }
}
