//! One render as the plan gives it to the Blender worker: the camera, its seed and
//! samples, the EXR it writes, the image it is accumulated into, and the fields a
//! degradation adds (a motion blur render's camera path, a defocus render's lens). It is
//! the worker's frame too (`dataset/wire.rs`: a render request's `frames`), typed once:
//! the worker reads the fields it renders by and leaves the rest (kind, phase, half,
//! band), and [`Render::check`] refuses a frame no worker could render.
use super::region::Region;
use crate::error::{Error, Result};
use crate::plan::kind::ImageKind;
use serde::{Deserialize, Serialize};

/// The camera path of one Cycles motion blur render: 2^steps + 1 keys.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Motion {
    pub steps: u32,
    /// OpenGL camera-to-world matrices (row-major) at t_k = k / 2^steps.
    pub keys: Vec<[[f64; 4]; 4]>,
}

/// The thin lens of a defocus render ([`crate::plan::kinds::defocus`]).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Dof {
    /// Distance of the plane in focus along the viewing axis (world units).
    pub focus_distance: f64,
    /// Radius of the lens aperture (world units).
    pub aperture_radius: f64,
}

/// One render: the camera, its Cycles seed and samples, the EXR it writes, and the
/// view and image it is accumulated into. A caller's frame (an object's QA view, a
/// geometry render) may give only `c2w`, `seed` and `out`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Render {
    /// The view; with `level`, the image (and, without `call`, the render call).
    #[serde(default)]
    pub view: usize,
    /// The image's level directory: its `kind`'s ([`ImageKind::dir`]).
    #[serde(default)]
    pub level: String,
    #[serde(default)]
    pub kind: ImageKind,
    /// The render phase the builder renders it in, phases in ascending order (the
    /// sharp images first, whose QA gates the rest): its kind's ([`ImageKind::phase`]).
    #[serde(default)]
    pub phase: u32,
    /// OpenGL camera-to-world, row-major.
    pub c2w: [[f64; 4]; 4],
    pub seed: u32,
    /// Cycles samples of this render; None: the caller's (the sharp render's own count).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub samples: Option<u32>,
    /// Under sample subsets (issue 15): this render takes the samples [sample_offset,
    /// sample_offset + samples) of a Cycles sequence of `sample_sequence` samples.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_offset: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_sequence: Option<u32>,
    pub out: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<Motion>,
    /// The pixels this render traces: those of its render call, which contain every
    /// pixel that can see the object ([`super::region`]); None: the whole image.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub region: Option<Region>,
    /// Which Blender render call renders it: consecutive renders with one `call` are one
    /// animation job ([`super::region::render_calls`]); None: a call of its own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub call: Option<usize>,
    /// Under a render target ([`super::target`]): which of the image's two independent
    /// halves this render adds to (0 or 1); None: the image has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub half: Option<u32>,
    /// A defocus render's lens (issue 35); None: a pinhole camera.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dof: Option<Dof>,
    /// A rolling shutter's band ([`crate::plan::kinds::rolling`]): this render exposes
    /// only some rows of its image, one of the bands that tile it; None: every row.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub band: Option<Band>,
    /// A motion blur render through Cycles' rolling shutter: each row exposed at its own
    /// time along the keys, top row first; None: every row at once.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rolling_shutter: Option<bool>,
}

/// The rows a render exposes of its image: `rows` [top, bottom), one of `of` bands that
/// tile the image's rows once.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
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

    /// A frame a worker can render: finite cameras, a sample block with both ends, a
    /// motion path of 2^steps + 1 keys, a rolling shutter only along a motion path.
    pub fn check(&self) -> Result<()> {
        let finite = |m: &[[f64; 4]; 4]| m.iter().flatten().all(|x| x.is_finite());
        if !finite(&self.c2w)
            || self
                .motion
                .as_ref()
                .is_some_and(|m| !m.keys.iter().all(finite))
        {
            return Err(Error::Value(
                "render frame: c2w must be a finite 4x4 matrix".into(),
            ));
        }
        if self.sample_offset.is_some() != self.sample_sequence.is_some() {
            return Err(Error::Value(
                "render frame: sample_offset and sample_sequence go together".into(),
            ));
        }
        if self.rolling_shutter == Some(true) && self.motion.is_none() {
            return Err(Error::Value(
                "render frame: a rolling shutter needs a motion path".into(),
            ));
        }
        if let Some(m) = &self.motion {
            let want = (1usize << m.steps.min(16)) + 1;
            if m.keys.len() != want {
                return Err(Error::Value(format!(
                    "render frame: motion of {} steps has {} keys, not {want}",
                    m.steps,
                    m.keys.len()
                )));
            }
        }
        Ok(())
    }

    /// The share of a whole image one frame of this render's image is in its mean's
    /// weight: 1, or 1/n for each of n bands that tile the image (each pixel gets one).
    pub fn share(&self) -> f64 {
        self.band.map_or(1.0, |b| 1.0 / f64::from(b.of.max(1)))
    }
}
