//! The worker contract (issue 49): the JSON lines between the builder and a Blender worker
//! (`blender_scripts/worker.py`, and the tests' stand-in), typed once.
//!
//! A request goes to the worker's stdin, one object a line; its replies come back one
//! object a line. `schemas/worker_request.schema.json` and `worker_reply.schema.json` are
//! these types' schemas (`make schemas`); tests check every message the real worker and
//! the stand-in exchange against them. The builder's render dicts become a request's
//! frames here ([`wire_frame`]), so the spelling of a frame lives in one place.
use super::meta::{DeviceRecord, LightPathsRecord};
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A camera-to-world matrix, OpenGL axes, row-major.
pub type Matrix = [[f64; 4]; 4];

/// The camera path of one Cycles motion blur render: 2^steps + 1 keys.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WireMotion {
    pub steps: u32,
    pub keys: Vec<Matrix>,
}

/// A defocus render's thin lens (world units).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WireDof {
    pub focus_distance: f64,
    pub aperture_radius: f64,
}

/// One frame of a render request.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WireFrame {
    pub c2w: Matrix,
    /// Cycles seed (the worker folds it into Cycles' signed 32-bit range).
    pub seed: u64,
    /// The EXR the worker writes, an absolute path.
    pub out: String,
    /// This frame's samples; absent: the request's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub samples: Option<u32>,
    /// With `sample_sequence`: the samples [offset, offset + samples) of a sequence of
    /// that many (Cycles sample subsets).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_offset: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_sequence: Option<u32>,
    /// One Cycles motion blur render along these keys instead of one camera.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<WireMotion>,
    /// The pixels [x0, y0, x1, y1) that can see the object; absent: the whole image.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub region: Option<[u32; 4]>,
    /// A thin lens; absent: the pinhole camera.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dof: Option<WireDof>,
    /// With `motion`: Cycles' rolling shutter, rows exposed top to bottom along the keys.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rolling_shutter: Option<bool>,
    /// The render call it belongs to: consecutive frames of one call are one job.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub call: Option<u64>,
    /// Without `call`: consecutive frames of one view and level are one job.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub view: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub level: Option<String>,
}

/// `{"cmd":"load"}`: import, normalize and light one GLB.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LoadRequest {
    pub glb: String,
    /// Where the worker writes the normalized object's vertices (.npy, float32, N×3).
    pub vertices_out: String,
    /// How a model whose every material is unlit renders: "lit" or "emission".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unlit: Option<String>,
    /// "auto" (bounces from what the materials need) or "fixed".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_paths: Option<String>,
}

/// `{"cmd":"render"}`: render frames in order, one reply per frame on disk, then one.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RenderRequest {
    pub resolution: u32,
    pub fov_deg: f64,
    /// Samples of every frame that carries none.
    pub samples: u32,
    pub frames: Vec<WireFrame>,
    /// The EXRs' codec (default NONE).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exr_codec: Option<String>,
    /// Cycles adaptive sampling at this threshold (off without).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_threshold: Option<f64>,
    /// false: a render call per frame instead of one job per run of a call's frames.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub batch: Option<bool>,
    /// A frame rendered in a region writes only its pixels (its reply's `origin`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crop: Option<bool>,
    /// Multi-layer EXRs with Cycles' denoising guide passes (albedo, normal).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub guides: Option<bool>,
    /// Multi-layer EXRs with the Depth and Normal data passes at each pixel's centre.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub geometry: Option<bool>,
}

/// What the builder sends: a line each.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(tag = "cmd", rename_all = "snake_case")]
pub enum Request {
    Load(LoadRequest),
    Render(RenderRequest),
    /// Exit 0.
    Quit,
}

/// The compute capabilities of the GPUs a CUDA or OptiX worker sees, and the archs Cycles
/// ships kernels for: the driver compiles the rest before the first frame.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CudaArchs {
    pub archs: Vec<String>,
    pub kernels: Vec<String>,
    /// The CUDA driver's version (cuDriverGetVersion: 13000 is 13.0).
    pub driver: i64,
}

/// The worker's first line, before any request.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Ready {
    pub ok: bool,
    pub ready: bool,
    pub blender: String,
    pub blender_version: String,
    pub pid: u32,
    pub device: DeviceRecord,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cuda: Option<CudaArchs>,
}

/// A GLB loaded: the normalized object and how it will render.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Loaded {
    pub ok: bool,
    /// The normalized object's box (its largest side 1).
    pub bbox_dims: [f64; 3],
    pub n_vertices: u64,
    pub n_triangles: u64,
    /// The scale and centre that normalized it.
    pub scale: f64,
    pub center: [f64; 3],
    pub warnings: Vec<String>,
    /// Unlit materials were rewritten to emission.
    pub unlit_fixed: bool,
    pub light_paths: LightPathsRecord,
    pub device: DeviceRecord,
    pub seconds: f64,
}

/// One frame on disk.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FrameDone {
    /// Its index in the request's frames.
    pub frame: u64,
    pub out: String,
    pub seconds: f64,
    /// Where a cropped EXR's pixels sit in the image; null: a whole image (always sent).
    #[schemars(required, extend("type" = ["array", "null"]))]
    pub origin: Option<[u32; 2]>,
}

/// A render request done.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Rendered {
    pub ok: bool,
    /// Frames rendered: all of the request's.
    pub done: u64,
    /// Render operator calls it took.
    pub jobs: u64,
}

/// A request refused or failed; the worker goes on.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Refused {
    pub ok: bool,
    /// One line.
    pub reason: String,
}

/// `--probe`'s one line: the Cycles devices that exist, by backend.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Probe {
    pub ok: bool,
    pub devices: BTreeMap<String, Vec<String>>,
    pub blender: String,
}

/// What the worker sends: a line each, told apart by their fields.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(untagged)]
pub enum Reply {
    Ready(Ready),
    Loaded(Loaded),
    FrameDone(FrameDone),
    Rendered(Rendered),
    Refused(Refused),
    Probe(Probe),
}

/// A render as the builder holds it (the plan's renders and the frames callers make):
/// every wire field, and whatever else it carries (its kind, half, …), which the worker
/// does not read.
#[derive(Deserialize)]
pub struct LooseFrame {
    c2w: Matrix,
    seed: u64,
    out: String,
    #[serde(default)]
    samples: Option<u32>,
    #[serde(default)]
    sample_offset: Option<u32>,
    #[serde(default)]
    sample_sequence: Option<u32>,
    #[serde(default)]
    motion: Option<WireMotion>,
    #[serde(default)]
    region: Option<[u32; 4]>,
    #[serde(default)]
    dof: Option<WireDof>,
    #[serde(default)]
    rolling_shutter: Option<bool>,
    #[serde(default)]
    call: Option<u64>,
    #[serde(default)]
    view: Option<u64>,
    #[serde(default)]
    level: Option<String>,
}

/// The wire frame of a render the builder holds: its wire fields, typed and checked
/// (finite cameras; a sample block has both ends; a motion path has 2^steps + 1 keys).
pub fn wire_frame(f: LooseFrame) -> Result<WireFrame> {
    let finite = |m: &Matrix| m.iter().flatten().all(|x| x.is_finite());
    if !finite(&f.c2w)
        || f.motion
            .as_ref()
            .is_some_and(|m| !m.keys.iter().all(finite))
    {
        return Err(Error::Value(
            "render frame: c2w must be a finite 4x4 matrix".into(),
        ));
    }
    if f.sample_offset.is_some() != f.sample_sequence.is_some() {
        return Err(Error::Value(
            "render frame: sample_offset and sample_sequence go together".into(),
        ));
    }
    if f.rolling_shutter == Some(true) && f.motion.is_none() {
        return Err(Error::Value(
            "render frame: a rolling shutter needs a motion path".into(),
        ));
    }
    if let Some(m) = &f.motion {
        let want = (1usize << m.steps.min(16)) + 1;
        if m.keys.len() != want {
            return Err(Error::Value(format!(
                "render frame: motion of {} steps has {} keys, not {want}",
                m.steps,
                m.keys.len()
            )));
        }
    }
    Ok(WireFrame {
        c2w: f.c2w,
        seed: f.seed,
        out: f.out,
        samples: f.samples,
        sample_offset: f.sample_offset,
        sample_sequence: f.sample_sequence,
        motion: f.motion,
        region: f.region,
        dof: f.dof,
        rolling_shutter: f.rolling_shutter,
        call: f.call,
        view: f.view,
        level: f.level,
    })
}

/// The schemas of the two directions, by file stem (`schemas/<stem>.schema.json`).
pub fn schemas() -> Vec<(&'static str, serde_json::Value)> {
    let mut out = vec![];
    for (stem, s, title) in [
        (
            "worker_request",
            schemars::schema_for!(Request),
            "A request to a blurset Blender worker (one JSON line on its stdin)",
        ),
        (
            "worker_reply",
            schemars::schema_for!(Reply),
            "A reply of a blurset Blender worker (one JSON line on its stdout)",
        ),
    ] {
        let mut v = s.to_value();
        if let Some(obj) = v.as_object_mut() {
            obj.insert("title".into(), title.into());
        }
        out.push((stem, v));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn frame(v: serde_json::Value) -> Result<WireFrame> {
        let f: LooseFrame =
            serde_json::from_value(v).map_err(|e| Error::Value(format!("render frame: {e}")))?;
        wire_frame(f)
    }

    const EYE: Matrix = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 3.0],
        [0.0, 0.0, 0.0, 1.0],
    ];

    #[test]
    fn a_plan_render_keeps_its_wire_fields_only() {
        let f = frame(json!({
            "c2w": EYE, "seed": 7, "out": "/x/a.exr", "samples": 4, "sample_offset": 8,
            "sample_sequence": 64, "region": [0, 0, 16, 16], "call": 3, "view": 1,
            "level": "blur_2", "kind": {"Blur": 2}, "phase": 1, "half": 0,
        }))
        .expect("a plan render is a frame");
        let v = serde_json::to_value(&f).expect("a frame serializes");
        let keys: Vec<&str> = v
            .as_object()
            .expect("an object")
            .keys()
            .map(|k| k.as_str())
            .collect();
        let mut want = [
            "c2w",
            "seed",
            "out",
            "samples",
            "sample_offset",
            "sample_sequence",
            "region",
            "call",
            "view",
            "level",
        ];
        want.sort_unstable();
        assert_eq!(keys, want);
        // What the worker reads back is what was sent.
        let back: WireFrame = serde_json::from_value(v).expect("the worker reads it back");
        assert_eq!(back, f);
    }

    #[test]
    fn a_half_sample_block_or_a_short_motion_path_is_refused() {
        let e = frame(json!({"c2w": EYE, "seed": 1, "out": "a", "sample_offset": 4}));
        assert!(e.is_err_and(|e| e.to_string().contains("sample_sequence")));
        let e = frame(json!({"c2w": EYE, "seed": 1, "out": "a",
                                  "motion": {"steps": 1, "keys": [EYE, EYE]}}));
        assert!(e.is_err_and(|e| e.to_string().contains("not 3")));
        let e = frame(json!({"seed": 1, "out": "a"}));
        assert!(e.is_err_and(|e| e.to_string().contains("c2w")));
        let mut bad = EYE;
        bad[1][2] = f64::NAN;
        let f = LooseFrame {
            c2w: bad,
            ..loose()
        };
        assert!(wire_frame(f).is_err_and(|e| e.to_string().contains("finite")));
    }

    #[test]
    fn a_worker_reply_with_a_field_the_contract_lacks_is_no_reply() {
        let ok = json!({"frame": 0, "out": "a.exr", "seconds": 0.1, "origin": null});
        assert!(matches!(
            serde_json::from_value::<Reply>(ok),
            Ok(Reply::FrameDone(_))
        ));
        let odd = json!({"frame": 0, "out": "a.exr", "seconds": 0.1, "origin": null, "x": 1});
        assert!(serde_json::from_value::<Reply>(odd).is_err());
        let quit: Request = serde_json::from_value(json!({"cmd": "quit"})).expect("quit");
        assert_eq!(quit, Request::Quit);
    }

    fn loose() -> LooseFrame {
        serde_json::from_value(json!({"c2w": EYE, "seed": 1, "out": "a"})).expect("a frame")
    }
}
