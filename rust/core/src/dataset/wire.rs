//! The worker contract (issue 49): the JSON lines between the builder and a Blender worker
//! (`blender_scripts/worker.py`, and the tests' stand-in), typed once.
//!
//! A request goes to the worker's stdin, one object a line; its replies come back one
//! object a line. `schemas/worker_request.schema.json` and `worker_reply.schema.json` are
//! these types' schemas (`make schemas`); tests check every message the real worker and
//! the stand-in exchange against them. A request's frames are the plan's [`Render`]s
//! ([`RenderRequest::line`] checks them), so a frame is spelled in one place. Every
//! request line is made here ([`Request::line`]); every reply line is typed here
//! ([`Reply::read`]) before the builder acts on it.
use super::meta::{DeviceRecord, LightPathsRecord};
use crate::error::{Error, Result};
use crate::plan::choices::LightPaths;
use crate::plan::render::Render;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A camera-to-world matrix, OpenGL axes, row-major.
pub type Matrix = [[f64; 4]; 4];

/// `{"cmd":"load"}`: import, normalize and light one GLB.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LoadRequest {
    pub glb: String,
    /// Where the worker writes the normalized object's vertices (.npy, float32, N×3).
    pub vertices_out: String,
    /// How a model whose every material is unlit renders (default lit).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unlit: Option<Unlit>,
    /// The bounce limits: from what the materials need, or fixed (default auto).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_paths: Option<LightPaths>,
}

/// How a model whose every material is unlit (camera-only emission) renders.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Unlit {
    /// As its materials say, under the scene's lights.
    Lit,
    /// Its unlit materials rewritten to emission of their colour.
    Emission,
}

/// `{"cmd":"render"}`: render frames in order, one reply per frame on disk, then one.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RenderRequest {
    pub resolution: u32,
    pub fov_deg: f64,
    /// Samples of every frame that carries none.
    pub samples: u32,
    /// The renders, as the plan spells them ([`Render`]): the worker reads the camera,
    /// seed, EXR, samples and sample block, motion path, region, lens, rolling shutter and
    /// render call of each, and leaves the rest.
    pub frames: Vec<Render>,
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
    // Required, as the schema says: serde reads a missing Option as None without this.
    #[serde(deserialize_with = "Option::deserialize")]
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

impl Request {
    /// The request as the line the worker reads (one JSON object, no newline).
    pub fn line(&self) -> Result<String> {
        serde_json::to_string(self).map_err(|e| Error::Value(e.to_string()))
    }
}

impl LoadRequest {
    /// The load request as the line the worker reads.
    pub fn line(self) -> Result<String> {
        Request::Load(self).line()
    }
}

impl RenderRequest {
    /// The request as the line the worker reads: every frame checked ([`Render::check`])
    /// and its EXR path made absolute (the worker runs in a folder of its own).
    pub fn line(mut self) -> Result<String> {
        for f in &mut self.frames {
            f.check()?;
            let out = std::path::absolute(&f.out)
                .map_err(|e| Error::io("cannot resolve", std::path::Path::new(&f.out), e))?;
            f.out = out.display().to_string();
        }
        Request::Render(self).line()
    }
}

/// The field that only one reply has, in the order they are tried.
const REPLY_MARKS: [&str; 6] = ["ready", "bbox_dims", "frame", "done", "reason", "devices"];

impl Reply {
    /// A line the worker sent (parsed JSON), typed: which reply it is follows from the
    /// field only that reply has ([`REPLY_MARKS`]), and the rest must fit that reply's
    /// type. The error names the reply and the field that does not fit, or says that
    /// no reply has its fields.
    pub fn read(value: &serde_json::Value) -> Result<Reply> {
        fn typed<T: serde::de::DeserializeOwned>(kind: &str, v: &serde_json::Value) -> Result<T> {
            serde_path_to_error::deserialize(v).map_err(|e| {
                Error::Value(format!(
                    "worker {kind} reply does not fit the contract at {}: {}",
                    e.path(),
                    e.inner()
                ))
            })
        }
        let mark = REPLY_MARKS.into_iter().find(|m| value.get(m).is_some());
        Ok(match mark {
            Some("ready") => Reply::Ready(typed("ready", value)?),
            Some("bbox_dims") => Reply::Loaded(typed("loaded", value)?),
            Some("frame") => Reply::FrameDone(typed("frame_done", value)?),
            Some("done") => Reply::Rendered(typed("rendered", value)?),
            Some("reason") => Reply::Refused(typed("refused", value)?),
            Some(_) => Reply::Probe(typed("probe", value)?),
            None => {
                let keys: Vec<&str> = match value.as_object() {
                    Some(o) => o.keys().map(String::as_str).collect(),
                    None => vec![],
                };
                return Err(Error::Value(format!(
                    "a worker line that is no reply of the contract (fields: {})",
                    keys.join(", ")
                )));
            }
        })
    }

    /// Which reply it is: ready, loaded, frame_done, rendered, refused or probe.
    pub fn kind(&self) -> &'static str {
        match self {
            Reply::Ready(_) => "ready",
            Reply::Loaded(_) => "loaded",
            Reply::FrameDone(_) => "frame_done",
            Reply::Rendered(_) => "rendered",
            Reply::Refused(_) => "refused",
            Reply::Probe(_) => "probe",
        }
    }
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

    const EYE: Matrix = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 3.0],
        [0.0, 0.0, 0.0, 1.0],
    ];

    /// Lines the real worker (blender_scripts/worker.py, bpy 5.0.1, CPU) sent: ready, a
    /// refused load, a load, a frame on disk, the render done, and its --probe line
    /// (tests/test_worker_contract.py reads the same file).
    const REAL_LINES: &str = include_str!("../../testdata/worker_lines.jsonl");

    fn real_line(i: usize) -> serde_json::Value {
        let line = REAL_LINES.lines().nth(i).unwrap_or_default();
        serde_json::from_str(line).unwrap_or_default()
    }

    fn line(frames: serde_json::Value) -> Result<String> {
        let frames: Vec<Render> = serde_json::from_value(frames)
            .map_err(|e| Error::Value(format!("render frame: {e}")))?;
        let req = RenderRequest {
            resolution: 8,
            fov_deg: 40.0,
            samples: 1,
            frames,
            exr_codec: None,
            noise_threshold: None,
            batch: None,
            crop: None,
            guides: None,
            geometry: None,
        };
        req.line()
    }

    #[test]
    fn a_plan_render_is_the_frame_the_worker_reads_back() {
        let render = json!({
            "c2w": EYE, "seed": 7, "out": "/x/a.exr", "samples": 4, "sample_offset": 8,
            "sample_sequence": 64, "region": [0, 0, 16, 16], "call": 3, "view": 1,
            "level": "blur_2", "kind": {"type": "blur", "level": 2}, "phase": 1, "half": 0,
        });
        let text = line(json!([render.clone()])).expect("a plan render is a frame");
        let back: Request = serde_json::from_str(&text).expect("the worker reads it back");
        let Request::Render(r) = back else {
            panic!("a render request")
        };
        assert_eq!(serde_json::to_value(&r.frames[0]).ok(), Some(render));
        // A caller's frame: a camera, a seed and an EXR, made absolute.
        let text = line(json!([{"c2w": EYE, "seed": 1, "out": "a.exr"}])).expect("a frame");
        let v: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
        let out = v["frames"][0]["out"].as_str().unwrap_or_default();
        assert!(
            std::path::Path::new(out).is_absolute() && out.ends_with("a.exr"),
            "{out}"
        );
    }

    #[test]
    fn a_half_sample_block_a_short_motion_path_or_an_odd_field_is_refused() {
        let e = line(json!([{"c2w": EYE, "seed": 1, "out": "a", "sample_offset": 4}]));
        assert!(e.is_err_and(|e| e.to_string().contains("sample_sequence")));
        let e = line(json!([{"c2w": EYE, "seed": 1, "out": "a",
                              "motion": {"steps": 1, "keys": [EYE, EYE]}}]));
        assert!(e.is_err_and(|e| e.to_string().contains("not 3")));
        let e = line(json!([{"seed": 1, "out": "a"}]));
        assert!(e.is_err_and(|e| e.to_string().contains("c2w")));
        let e = line(json!([{"c2w": EYE, "seed": 1, "out": "a", "sampels": 2}]));
        assert!(e.is_err_and(|e| e.to_string().contains("sampels")));
        let e = line(json!([{"c2w": EYE, "seed": 1, "out": "a", "rolling_shutter": true}]));
        assert!(e.is_err_and(|e| e.to_string().contains("motion path")));
        let mut bad: Render =
            serde_json::from_value(json!({"c2w": EYE, "seed": 1, "out": "a"})).expect("a frame");
        bad.c2w[1][2] = f64::NAN;
        assert!(bad.check().is_err_and(|e| e.to_string().contains("finite")));
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

    #[test]
    fn the_load_and_quit_lines_are_the_contracts() {
        let load = LoadRequest {
            glb: "/m/a.glb".into(),
            vertices_out: "/w/v.npy".into(),
            unlit: Some(Unlit::Lit),
            light_paths: Some(LightPaths::Fixed),
        };
        let text = load.clone().line().expect("a load line");
        let v: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
        assert_eq!(
            v,
            json!({"cmd": "load", "glb": "/m/a.glb", "vertices_out": "/w/v.npy",
                   "unlit": "lit", "light_paths": "fixed"})
        );
        let back: Request = serde_json::from_str(&text).expect("the worker reads it back");
        assert_eq!(back, Request::Load(load));
        let bare: Request = serde_json::from_value(json!({"cmd": "load", "glb": "a",
                                                           "vertices_out": "v"}))
        .expect("unlit and light_paths may go unsaid");
        assert!(matches!(
            bare,
            Request::Load(LoadRequest {
                unlit: None,
                light_paths: None,
                ..
            })
        ));
        let odd = json!({"cmd": "load", "glb": "a", "vertices_out": "v", "unlit": "glow"});
        assert!(serde_json::from_value::<Request>(odd).is_err());
        assert_eq!(
            Request::Quit.line().ok().as_deref(),
            Some(r#"{"cmd":"quit"}"#)
        );
    }

    #[test]
    fn every_line_of_the_real_worker_reads_as_its_reply_field_for_field() {
        let kinds: Vec<&str> = REAL_LINES
            .lines()
            .map(|line| {
                let v: serde_json::Value = serde_json::from_str(line).expect("JSON");
                let reply = Reply::read(&v).unwrap_or_else(|e| panic!("{line}: {e}"));
                // Typed, nothing is lost: the same fields and values (floats exactly).
                assert_eq!(serde_json::to_value(&reply).ok(), Some(v), "{line}");
                reply.kind()
            })
            .collect();
        let want = [
            "ready",
            "refused",
            "loaded",
            "frame_done",
            "rendered",
            "probe",
        ];
        assert_eq!(kinds, want);
        // A GPU worker's ready line: its CUDA archs typed too.
        let mut gpu = real_line(0);
        gpu["device"] = json!({"backend": "OPTIX", "devices": ["NVIDIA H100"], "kernel": "OPTIX"});
        gpu["cuda"] = json!({"archs": ["sm_90"], "kernels": ["sm_86", "sm_89"], "driver": 13000});
        let Ok(Reply::Ready(ready)) = Reply::read(&gpu) else {
            panic!("a GPU ready line")
        };
        assert_eq!(ready.cuda.map(|c| c.driver), Some(13000));
        assert_eq!(ready.device.backend, "OPTIX");
    }

    #[test]
    fn a_null_is_read_where_the_contract_allows_one_and_named_where_not() {
        // "cuda": null reads as no CUDA facts; the typed value would drop the key, so the
        // bindings hand Python the line as sent (tests/test_worker_contract.py).
        let mut ready = real_line(0);
        ready["cuda"] = serde_json::Value::Null;
        assert!(matches!(
            Reply::read(&ready),
            Ok(Reply::Ready(Ready { cuda: None, .. }))
        ));
        let frame = json!({"frame": 0, "out": "a.exr", "seconds": 0.1, "origin": null});
        assert!(matches!(
            Reply::read(&frame),
            Ok(Reply::FrameDone(FrameDone { origin: None, .. }))
        ));
        // Its origin is always sent: one missing is no frame reply (the schema's rule).
        let e = Reply::read(&json!({"frame": 0, "out": "a.exr", "seconds": 0.1}));
        assert!(e.is_err_and(|e| e.to_string().contains("origin")));
        // A device field sent as null is no device record: the error names it.
        ready["device"]["kernel"] = serde_json::Value::Null;
        let e = Reply::read(&ready)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("ready") && e.contains("device.kernel"), "{e}");
        let mut loaded = real_line(2);
        loaded["n_vertices"] = json!(-1);
        let e = Reply::read(&loaded)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("loaded") && e.contains("n_vertices"), "{e}");
        loaded["n_vertices"] = json!(24);
        loaded["bbox"] = json!([1, 1, 1]);
        let e = Reply::read(&loaded)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("bbox"), "{e}");
        let e = Reply::read(&json!({"ok": true, "hello": 1}))
            .err()
            .map(|e| e.to_string());
        assert!(e.is_some_and(|e| e.contains("no reply") && e.contains("hello")));
        assert!(Reply::read(&json!([1, 2])).is_err());
    }
}
