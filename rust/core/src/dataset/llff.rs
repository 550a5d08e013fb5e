//! LLFF scene I/O: `poses_bounds.npy` and `transforms.json`.
//!
//! `poses_bounds.npy` is N × 17 float64: the 3 × 5 matrix [R | t | hwf] of a
//! camera-to-world pose with columns [down, right, backwards], flattened row-major,
//! then near and far. This is what IBRNet / NAN / GeoNeRF loaders read; they turn the
//! columns into OpenGL [right, up, backwards] themselves.
use crate::error::{Error, Result};
use crate::ground::atomic::write_atomic;
use crate::ground::limits::{self, MAX_POSE_ROWS};
use crate::ground::names::image_name;
use crate::plan::sampling::SettingPlan;
use glam::DMat4;
use std::path::Path;

/// One row of `poses_bounds.npy`.
pub type PoseRow = [f64; 17];

/// The LLFF row of an OpenGL camera-to-world matrix (columns right, up, backwards).
pub fn row_from_c2w_gl(c2w: &DMat4, hwf: [f64; 3], near: f64, far: f64) -> PoseRow {
    let (right, up, back, t) = (
        c2w.x_axis.truncate(),
        c2w.y_axis.truncate(),
        c2w.z_axis.truncate(),
        c2w.w_axis.truncate(),
    );
    let cols = [-up, right, back, t];
    let mut row = [0.0; 17];
    for i in 0..3 {
        for (j, c) in cols.iter().enumerate() {
            row[i * 5 + j] = c[i];
        }
        row[i * 5 + 4] = hwf[i];
    }
    row[15] = near;
    row[16] = far;
    row
}

fn npy_bytes(rows: &[PoseRow]) -> Vec<u8> {
    let dict = format!(
        "{{'descr': '<f8', 'fortran_order': False, 'shape': ({}, 17), }}",
        rows.len()
    );
    // magic(6) + version(2) + len(2) + dict + padding + '\n' is a multiple of 64.
    let unpadded = 10 + dict.len() + 1;
    let pad = (64 - unpadded % 64) % 64;
    let header = format!("{dict}{}\n", " ".repeat(pad));
    let mut out = Vec::with_capacity(10 + header.len() + rows.len() * 17 * 8);
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for r in rows {
        for v in r {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

/// What is wrong with row `i` (view `i`) of a pose file, or None: every value finite
/// (a NaN silently poisons training), hwf positive (loaders divide by the focal
/// length), and bounds with 0 < near < far (loaders sample rays between the two: an
/// empty, reversed or negative interval, such as near = far = -1 for "unknown", breaks
/// them). The one check of the writer and the reader.
fn row_problem(i: usize, row: &PoseRow) -> Option<String> {
    if let Some(j) = row.iter().position(|v| !v.is_finite()) {
        return Some(format!("row {i} column {j} is not finite"));
    }
    if let Some((name, v)) = [("height", row[4]), ("width", row[9]), ("focal", row[14])]
        .into_iter()
        .find(|(_, v)| *v <= 0.0)
    {
        return Some(format!("row {i}: {name} {v} (hwf must be positive)"));
    }
    let (near, far) = (row[15], row[16]);
    if !(near > 0.0 && far > near) {
        return Some(format!(
            "row {i} (view {i}): near {near} and far {far} are no depth bounds \
             (need 0 < near < far)"
        ));
    }
    None
}

/// Write `poses_bounds.npy` atomically. A row the reader would refuse (`row_problem`:
/// a value not finite, no camera, bounds not 0 < near < far) is refused, named, and
/// nothing is written.
pub fn write_poses_bounds(path: &Path, rows: &[PoseRow]) -> Result<()> {
    if let Some(reason) = rows.iter().enumerate().find_map(|(i, r)| row_problem(i, r)) {
        return Err(Error::PoseFormat {
            reason,
            path: path.into(),
        });
    }
    write_atomic(path, &npy_bytes(rows))
}

fn header_field<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let start = header.find(&format!("'{key}'"))? + key.len() + 2;
    let rest = header[start..].trim_start().strip_prefix(':')?.trim_start();
    if let Some(r) = rest.strip_prefix('(') {
        return r.find(')').map(|e| &r[..e]);
    }
    if let Some(r) = rest.strip_prefix('\'') {
        return r.find('\'').map(|e| &r[..e]);
    }
    let end = rest.find([',', '}']).unwrap_or(rest.len());
    Some(rest[..end].trim())
}

/// Read `poses_bounds.npy` (float64 or float32, N × 17, C order).
pub fn read_poses_bounds(path: &Path) -> Result<Vec<PoseRow>> {
    // A file past MAX_POSE_ROWS of float64 (and a header) is refused before it is read.
    let most = (MAX_POSE_ROWS * 17 * 8 + (1 << 16)) as u64;
    let len = std::fs::metadata(path)
        .map_err(|e| Error::io("cannot read pose file", path, e))?
        .len();
    limits::check("file of bytes", len, most, "MAX_POSE_ROWS rows of float64").map_err(
        |reason| Error::PoseFormat {
            reason,
            path: path.into(),
        },
    )?;
    let bytes = std::fs::read(path).map_err(|e| Error::io("cannot read pose file", path, e))?;
    parse_poses_bounds(&bytes).map_err(|reason| Error::PoseFormat {
        reason,
        path: path.into(),
    })
}

/// The rows of a `poses_bounds.npy` held in memory; the error is the reason, for the
/// caller to pair with its file. Arbitrary bytes give an error, never a panic (fuzzed).
pub fn parse_poses_bounds(bytes: &[u8]) -> std::result::Result<Vec<PoseRow>, String> {
    let (header, data) = npy_parts(bytes)?;
    let descr = header_field(header, "descr").ok_or("no descr")?;
    if header_field(header, "fortran_order") == Some("True") {
        return Err("Fortran order is not supported".into());
    }
    let n = pose_rows_of(header)?;
    let width = match descr {
        "<f8" => 8,
        "<f4" => 4,
        d => return Err(format!("dtype {d:?}, expected float64 or float32")),
    };
    let need = n
        .checked_mul(17 * width)
        .ok_or_else(|| format!("shape ({n}, 17) is too large"))?;
    if data.len() < need {
        return Err(format!(
            "{} bytes of data for {n} rows, expected {need}",
            data.len()
        ));
    }
    let mut rows = Vec::with_capacity(n);
    for (i, chunk) in data[..need].chunks_exact(17 * width).enumerate() {
        let mut row = [0.0; 17];
        for (v, b) in row.iter_mut().zip(chunk.chunks_exact(width)) {
            *v = match *b {
                [a0, a1, a2, a3, a4, a5, a6, a7] => {
                    f64::from_le_bytes([a0, a1, a2, a3, a4, a5, a6, a7])
                }
                [a0, a1, a2, a3] => f64::from(f32::from_le_bytes([a0, a1, a2, a3])),
                _ => return Err("short value".into()),
            };
        }
        if let Some(reason) = row_problem(i, &row) {
            return Err(reason);
        }
        rows.push(row);
    }
    Ok(rows)
}

/// A .npy file's header text and the bytes after it.
fn npy_parts(bytes: &[u8]) -> std::result::Result<(&str, &[u8]), String> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err("not a .npy file".into());
    }
    let (hlen, hstart): (usize, usize) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(format!("unsupported .npy version {v}")),
    };
    let header = hstart
        .checked_add(hlen)
        .and_then(|end| bytes.get(hstart..end))
        .and_then(|h| std::str::from_utf8(h).ok())
        .ok_or("truncated header")?;
    Ok((header, &bytes[hstart + hlen..]))
}

/// N of a header's shape (N, 17), within [`MAX_POSE_ROWS`].
fn pose_rows_of(header: &str) -> std::result::Result<usize, String> {
    let shape: Vec<usize> = header_field(header, "shape")
        .ok_or("no shape")?
        .split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|s| s.trim().parse::<usize>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| "unreadable shape")?;
    if shape.len() != 2 || shape[1] != 17 {
        return Err(format!("shape {shape:?}, expected (N, 17)"));
    }
    let n = shape[0];
    limits::check(
        &format!("shape ({n}, 17), rows"),
        n as u64,
        MAX_POSE_ROWS as u64,
        "MAX_POSE_ROWS",
    )?;
    Ok(n)
}

fn c2w_from_rows(rows: &[[f64; 4]; 4]) -> DMat4 {
    DMat4::from_cols_array_2d(rows).transpose()
}

/// The `poses_bounds.npy` rows of a setting: the pose at p for every view.
pub fn setting_rows(plan: &SettingPlan) -> Vec<PoseRow> {
    let [w, h] = plan.resolution;
    plan.views
        .iter()
        .map(|v| {
            row_from_c2w_gl(
                &c2w_from_rows(&v.c2w),
                [h as f64, w as f64, plan.focal_px],
                v.near,
                v.far,
            )
        })
        .collect()
}

/// The camera fields of a setting's `transforms.json` that every scene of it shares.
const CAMERA_KEYS: [&str; 9] = [
    "convention",
    "camera_angle_x",
    "camera_angle_y",
    "fl_x",
    "fl_y",
    "cx",
    "cy",
    "w",
    "h",
];

/// What a scene's transforms.json says of itself beside its setting's cameras.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SceneFields {
    /// The level directory it is a scene of (`sharp`, `blur_2`).
    pub level: String,
    /// The gain of a noisy copy.
    pub gain: Option<f64>,
    /// What its held-out views hold: `sharp` or `blurry` in a blur level, `clean` or
    /// `noisy` in a noisy copy.
    pub test_view_images: Option<String>,
}

impl SceneFields {
    fn map(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut m = serde_json::Map::new();
        m.insert("level".into(), self.level.clone().into());
        if let Some(g) = self.gain {
            // An integral gain reads as an integer, as the folder name gain_<g> does.
            let v = if g.fract() == 0.0 && g.abs() < 9.0e15 {
                serde_json::Value::from(g as i64)
            } else {
                serde_json::Value::from(g)
            };
            m.insert("gain".into(), v);
        }
        if let Some(t) = &self.test_view_images {
            m.insert("test_view_images".into(), t.clone().into());
        }
        m
    }
}

/// The `transforms.json` of one LLFF scene of a setting (a level directory, or a gain
/// of one), as nerfstudio's data parser reads it: the setting's cameras, one frame per
/// file (`files`: view index and path relative to the scene, e.g. `images/000.png`),
/// and `train_filenames` / `val_filenames` / `test_filenames` from the test views (val
/// = test, as nerfstudio's own split makes them), and the scene's own `fields`.
pub fn scene_transforms(
    setting: &serde_json::Value,
    files: &[(usize, String)],
    test_views: &[usize],
    fields: &SceneFields,
) -> Result<serde_json::Value> {
    let bad = |what: String| Error::Value(format!("setting transforms.json: {what}"));
    let mut doc = serde_json::Map::new();
    for k in CAMERA_KEYS {
        let v = setting.get(k).ok_or_else(|| bad(format!("no {k:?}")))?;
        doc.insert(k.into(), v.clone());
    }
    let by_view: std::collections::BTreeMap<u64, &serde_json::Value> = setting
        .get("frames")
        .and_then(|f| f.as_array())
        .ok_or_else(|| bad("no frames".into()))?
        .iter()
        .filter_map(|f| Some((f.get("index")?.as_u64()?, f)))
        .collect();
    let (mut frames, mut train, mut test) = (Vec::new(), Vec::new(), Vec::new());
    for (view, path) in files {
        let f = by_view
            .get(&(*view as u64))
            .ok_or_else(|| bad(format!("no frame of view {view}")))?;
        let mut frame = serde_json::Map::new();
        frame.insert("index".into(), (*view).into());
        frame.insert("file_path".into(), path.clone().into());
        for k in ["transform_matrix", "near", "far"] {
            if let Some(v) = f.get(k) {
                frame.insert(k.into(), v.clone());
            }
        }
        frames.push(serde_json::Value::Object(frame));
        if test_views.contains(view) {
            test.push(path.clone());
        } else {
            train.push(path.clone());
        }
    }
    doc.extend(fields.map());
    doc.insert("frames".into(), frames.into());
    doc.insert("train_filenames".into(), train.into());
    doc.insert("val_filenames".into(), test.clone().into());
    doc.insert("test_filenames".into(), test.into());
    Ok(serde_json::Value::Object(doc))
}

/// [`scene_transforms`] written atomically to `path`.
fn write_scene_doc(
    path: &Path,
    setting: &serde_json::Value,
    files: &[(usize, String)],
    test_views: &[usize],
    fields: &SceneFields,
) -> Result<()> {
    let doc = scene_transforms(setting, files, test_views, fields)?;
    let text = serde_json::to_string_pretty(&doc).map_err(|e| Error::Value(e.to_string()))?;
    write_atomic(path, text.as_bytes())
}

/// The transforms.json of one scene made from a setting's transforms.json at
/// `setting_path` (a noisy copy of a level), written atomically to `path`. A setting file
/// that cannot be read or lacks a camera field or a view's frame is one Input error
/// naming it; nothing is written then.
pub fn write_scene_transforms(
    path: &Path,
    setting_path: &Path,
    files: &[(usize, String)],
    test_views: &[usize],
    fields: &SceneFields,
) -> Result<()> {
    let bad = |reason: String| Error::Input {
        reason,
        path: setting_path.into(),
    };
    let text = std::fs::read(setting_path).map_err(|e| bad(format!("cannot read ({e})")))?;
    let setting: serde_json::Value = serde_json::from_slice(&text)
        .map_err(|e| bad(format!("transforms.json is not readable JSON ({e})")))?;
    write_scene_doc(path, &setting, files, test_views, fields).map_err(|e| match e {
        Error::Value(reason) => bad(reason),
        other => other,
    })
}

/// Write `<level>/poses_bounds.npy` and `<level>/transforms.json` for every level
/// directory of a setting, and the setting's `transforms.json` (OpenGL camera-to-world,
/// intrinsics, per-level paths). `test_views` are the held-out views; in the blur levels
/// their images are the sharp ones when `sharp_test_views` (Deblur-NeRF's convention).
pub fn write_setting_poses(
    plan: &SettingPlan,
    setting_dir: &Path,
    level_dirs: &[String],
    test_views: &[usize],
    sharp_test_views: bool,
) -> Result<()> {
    let rows = setting_rows(plan);
    for level in level_dirs {
        write_poses_bounds(&setting_dir.join(level).join("poses_bounds.npy"), &rows)?;
    }
    let doc = setting_transforms(plan, level_dirs);
    let text = serde_json::to_string_pretty(&doc).map_err(|e| Error::Value(e.to_string()))?;
    write_atomic(&setting_dir.join("transforms.json"), text.as_bytes())?;
    let n = plan.views.len();
    let files: Vec<(usize, String)> = plan
        .views
        .iter()
        .map(|v| (v.index, format!("images/{}", image_name(v.index, n))))
        .collect();
    for level in level_dirs {
        let fields = SceneFields {
            level: level.clone(),
            gain: None,
            test_view_images: (level != "sharp")
                .then(|| if sharp_test_views { "sharp" } else { "blurry" }.to_string()),
        };
        write_scene_doc(
            &setting_dir.join(level).join("transforms.json"),
            &doc,
            &files,
            test_views,
            &fields,
        )?;
    }
    Ok(())
}

/// The setting's transforms.json: the camera, and every view's pose at p with its
/// image in every level.
fn setting_transforms(plan: &SettingPlan, level_dirs: &[String]) -> serde_json::Value {
    let [w, h] = plan.resolution;
    let n = plan.views.len();
    let frames: Vec<serde_json::Value> = plan
        .views
        .iter()
        .map(|v| {
            let name = image_name(v.index, n);
            let paths: serde_json::Map<String, serde_json::Value> = level_dirs
                .iter()
                .map(|l| (l.clone(), format!("{l}/images/{name}").into()))
                .collect();
            serde_json::json!({
                "index": v.index,
                "file_path": format!("sharp/images/{name}"),
                "file_paths": paths,
                "transform_matrix": v.c2w,
                "near": v.near,
                "far": v.far,
            })
        })
        .collect();
    let fov = plan.fov_deg.to_radians();
    serde_json::json!({
        "convention": "OpenGL camera-to-world (x right, y up, z backwards); world +Z up; object centred at the origin, largest side 1",
        "camera_angle_x": fov,
        "camera_angle_y": fov,
        "fl_x": plan.focal_px,
        "fl_y": plan.focal_px,
        "cx": w as f64 / 2.0,
        "cy": h as f64 / 2.0,
        "w": w,
        "h": h,
        "levels": level_dirs.iter().map(|l| (l.clone(), serde_json::Value::from(format!("{l}/images")))).collect::<serde_json::Map<_, _>>(),
        "frames": frames,
    })
}

#[allow(clippy::unwrap_used)] // a failing unwrap is a failing test
#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec3, DVec4};
    use proptest::prelude::*;

    /// The OpenGL camera-to-world matrix, hwf and bounds of an LLFF row (the inverse of
    /// `row_from_c2w_gl`, which the tests check rows against).
    fn c2w_gl_from_row(row: &PoseRow) -> (DMat4, [f64; 3], f64, f64) {
        let col = |j: usize| DVec3::new(row[j], row[5 + j], row[10 + j]);
        let (down, right, back, t) = (col(0), col(1), col(2), col(3));
        let c2w = DMat4::from_cols(
            right.extend(0.0),
            (-down).extend(0.0),
            back.extend(0.0),
            DVec4::new(t.x, t.y, t.z, 1.0),
        );
        (c2w, [row[4], row[9], row[14]], row[15], row[16])
    }

    fn valid_npy(n: usize) -> Vec<u8> {
        let rows: Vec<PoseRow> = (0..n).map(|i| [i as f64 + 0.5; 17]).collect();
        npy_bytes(&rows)
    }

    #[test]
    fn absurd_shapes_are_errors_not_panics() {
        // 135637824071393762 · 17 · 8 wraps to 16 bytes in unchecked arithmetic.
        for shape in [
            "(18446744073709551615, 17)",
            "(135637824071393762, 17)",
            "(3,17,)",
        ] {
            let mut b = valid_npy(1);
            let text = String::from_utf8_lossy(&b[10..]).replace("(1, 17)", shape);
            b.truncate(10);
            b.extend_from_slice(text.as_bytes());
            assert!(parse_poses_bounds(&b).is_err(), "{shape}");
        }
        let mut v2 = valid_npy(2);
        v2[6] = 2; // version 2 with a header length past the end
        assert!(parse_poses_bounds(&v2).is_err());
    }

    #[test]
    fn a_file_promising_more_rows_than_the_limit_is_refused_named() -> Result<()> {
        let mut b = valid_npy(1);
        let text = String::from_utf8_lossy(&b[10..]).replace("(1, 17)", "(2000000, 17)");
        b.truncate(10);
        b.extend_from_slice(text.as_bytes());
        let e = parse_poses_bounds(&b).err().unwrap_or_default();
        assert!(
            e.contains("over the limit of 1048576 (MAX_POSE_ROWS)"),
            "{e}"
        );
        // A file larger than the most rows could fill is not read at all (sparse here).
        let p = tmp("huge.npy");
        let f = std::fs::File::create(&p).map_err(|e| Error::io("create", &p, e))?;
        f.set_len(200 << 20)
            .map_err(|e| Error::io("set_len", &p, e))?;
        let e = read_poses_bounds(&p)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            e.contains("MAX_POSE_ROWS rows of float64") && e.contains("huge.npy"),
            "{e}"
        );
        let _ = std::fs::remove_file(&p);
        Ok(())
    }

    // The reader's fuzz harness in `cargo test`: arbitrary bytes and mutations of a
    // valid file must give rows or an error, never a panic (rust/fuzz runs it longer).
    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]
        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
            let _ = parse_poses_bounds(&bytes);
        }

        #[test]
        fn mutated_files_never_panic(
            n in 0usize..4,
            edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..8),
            cut in any::<prop::sample::Index>(),
        ) {
            let mut b = valid_npy(n);
            for (at, v) in edits {
                let i = at.index(b.len());
                b[i] = v;
            }
            let keep = cut.index(b.len() + 1);
            b.truncate(keep);
            if let Ok(rows) = parse_poses_bounds(&b) {
                prop_assert!(rows.iter().flatten().all(|v| v.is_finite()));
            }
        }
    }

    fn tmp(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("blurset-llff-{}-{name}", std::process::id()))
    }

    #[test]
    fn npy_roundtrip() -> Result<()> {
        let rows: Vec<PoseRow> = (0..5)
            .map(|i| {
                let mut r = [0.0; 17];
                for (j, v) in r.iter_mut().enumerate() {
                    *v = (i * 17 + j) as f64 * 0.5 + 1.0;
                }
                r
            })
            .collect();
        let p = tmp("rt.npy");
        write_poses_bounds(&p, &rows)?;
        let bytes = std::fs::read(&p).map_err(|e| Error::io("read", &p, e))?;
        let hlen = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        assert_eq!((10 + hlen) % 64, 0);
        assert_eq!(read_poses_bounds(&p)?, rows);
        let _ = std::fs::remove_file(&p);
        Ok(())
    }

    #[test]
    fn a_camera_without_focal_length_is_refused_by_row() {
        let mut rows = vec![[1.0; 17]; 3];
        for r in &mut rows {
            r[16] = 2.0; // far beyond near
        }
        rows[2][14] = 0.0;
        let err = parse_poses_bounds(&npy_bytes(&rows)).unwrap_err();
        assert_eq!(err, "row 2: focal 0 (hwf must be positive)");
        rows[2][14] = 1.0;
        rows[1][9] = -4.0;
        let err = parse_poses_bounds(&npy_bytes(&rows)).unwrap_err();
        assert!(err.starts_with("row 1: width -4"), "{err}");
    }

    #[test]
    fn bounds_that_are_no_depth_interval_are_refused_named_and_not_written() {
        let mut good = [1.0; 17];
        good[16] = 2.0;
        for (near, far) in [
            (-1.0, -1.0),
            (0.0, 1.0),
            (2.0, 2.0),
            (3.0, 1.0),
            (-2.0, 5.0),
        ] {
            let mut rows = vec![good; 3];
            rows[1][15] = near;
            rows[1][16] = far;
            let p = tmp(&format!("bounds{near}_{far}.npy"));
            let err = write_poses_bounds(&p, &rows)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(
                err.contains("row 1 (view 1)")
                    && err.contains("0 < near < far")
                    && err.contains(&p.display().to_string()),
                "{err}"
            );
            assert!(!p.exists(), "{near} {far}: written");
            let read = parse_poses_bounds(&npy_bytes(&rows)).unwrap_err();
            assert!(read.starts_with("row 1 (view 1): near"), "{read}");
        }
        assert!(parse_poses_bounds(&npy_bytes(&[good])).is_ok());
    }

    #[test]
    fn refuses_nan_and_bad_shape() {
        let mut r = [1.0; 17];
        r[3] = f64::NAN;
        assert!(write_poses_bounds(&tmp("nan.npy"), &[r]).is_err());
        let p = tmp("shape.npy");
        let mut b = npy_bytes(&[[0.0; 17]]);
        if let Some(i) = b.windows(7).position(|w| w == b"(1, 17)") {
            b[i + 5] = b'5';
        }
        let _ = std::fs::write(&p, &b);
        let err = read_poses_bounds(&p)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("expected (N, 17)"), "{err}");
        let _ = std::fs::remove_file(&p);
    }

    #[test]
    fn setting_rows_point_at_the_object() -> Result<()> {
        let cfg = crate::plan::sampling_config::SamplingConfig {
            views: 5,
            latents: 2,
            ..Default::default()
        };
        let verts: Vec<[f32; 3]> = vec![[-0.5, -0.5, -0.5], [0.5, 0.5, 0.5]];
        let plan =
            crate::plan::sampling::plan_setting(&cfg, "u", 180.0, 4, [1.0, 1.0, 1.0], &verts)?;
        for (row, v) in setting_rows(&plan).iter().zip(&plan.views) {
            let (c2w, hwf, near, far) = c2w_gl_from_row(row);
            let eye = c2w.w_axis.truncate();
            let fwd = -c2w.z_axis.truncate();
            assert!(fwd.dot(-eye.normalize()) > 1.0 - 1e-12);
            assert!(near < eye.length() && eye.length() < far);
            assert_eq!(hwf, [512.0, 512.0, plan.focal_px]);
            assert!((eye.length() - v.r).abs() < 1e-9);
        }
        Ok(())
    }

    /// A 5-view setting with a sharp and a blur_2 level, its poses written (test views
    /// 0 and 4), in a fresh folder named after `tag`.
    fn written_setting(tag: &str) -> Result<std::path::PathBuf> {
        let cfg = crate::plan::sampling_config::SamplingConfig {
            views: 5,
            latents: 2,
            levels: vec![2],
            ..Default::default()
        };
        let verts: Vec<[f32; 3]> = vec![[-0.5, -0.5, -0.5], [0.5, 0.5, 0.5]];
        let plan = crate::plan::sampling::plan_setting(&cfg, "u", 0.0, 4, [1.0; 3], &verts)?;
        let dir = tmp(tag);
        let levels = ["sharp".to_string(), "blur_2".to_string()];
        for l in &levels {
            std::fs::create_dir_all(dir.join(l)).map_err(|e| Error::io("mkdir", &dir, e))?;
        }
        write_setting_poses(&plan, &dir, &levels, &[0, 4], true)?;
        Ok(dir)
    }

    fn read_json(p: std::path::PathBuf) -> Result<serde_json::Value> {
        let t = std::fs::read_to_string(&p).map_err(|e| Error::io("read", &p, e))?;
        serde_json::from_str(&t).map_err(|e| Error::Value(e.to_string()))
    }

    #[test]
    fn level_transforms_name_their_files_and_split_the_views() -> Result<()> {
        let dir = written_setting("setting")?;
        let read = read_json;
        let setting = read(dir.join("transforms.json"))?;
        let blur = read(dir.join("blur_2/transforms.json"))?;
        assert_eq!(blur["test_view_images"], "sharp");
        assert!(read(dir.join("sharp/transforms.json"))?
            .get("test_view_images")
            .is_none());
        assert_eq!(blur["fl_x"], setting["fl_x"]);
        assert_eq!(blur["frames"][1]["file_path"], "images/001.png");
        assert_eq!(
            blur["frames"][3]["transform_matrix"],
            setting["frames"][3]["transform_matrix"]
        );
        assert_eq!(
            blur["test_filenames"],
            serde_json::json!(["images/000.png", "images/004.png"])
        );
        assert_eq!(blur["val_filenames"], blur["test_filenames"]);
        assert_eq!(blur["train_filenames"].as_array().map(Vec::len), Some(3));
        let e = scene_transforms(&setting, &[(9, "x".into())], &[], &SceneFields::default())
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("view 9"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn a_noisy_scene_is_written_from_the_setting_file() -> Result<()> {
        let dir = written_setting("noisy-scene")?;
        let read = read_json;
        // A noisy copy's scene from the setting's file: an integral gain is an integer.
        let noisy = dir.join("gain.json");
        let fields = |gain| SceneFields {
            level: "blur_2".into(),
            gain: Some(gain),
            test_view_images: Some("clean".into()),
        };
        let files = [(0, "images/000.png".to_string())];
        write_scene_transforms(
            &noisy,
            &dir.join("transforms.json"),
            &files,
            &[0],
            &fields(4.0),
        )?;
        let doc = read(noisy.clone())?;
        assert_eq!(
            (doc["gain"].as_i64(), doc["level"].as_str()),
            (Some(4), Some("blur_2"))
        );
        write_scene_transforms(
            &noisy,
            &dir.join("transforms.json"),
            &files,
            &[0],
            &fields(2.5),
        )?;
        assert_eq!(read(noisy.clone())?["gain"].as_f64(), Some(2.5));
        // A setting file that is missing, or lacks a camera field, is an Input error
        // naming it, and nothing is written.
        let broken = dir.join("broken.json");
        std::fs::write(&broken, b"{\"frames\": []}").map_err(|e| Error::io("write", &broken, e))?;
        let out = dir.join("never.json");
        for setting in [dir.join("absent.json"), broken.clone()] {
            match write_scene_transforms(&out, &setting, &files, &[0], &fields(1.0)) {
                Err(Error::Input { path, .. }) => assert_eq!(path, setting),
                other => panic!("{other:?}"),
            }
        }
        assert!(!out.exists());
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn gl_llff_roundtrip() {
        let c2w = DMat4::from_rotation_z(0.3) * DMat4::from_rotation_x(1.1);
        let c2w = DMat4::from_translation(DVec3::new(1.0, 2.0, 3.0)) * c2w;
        let row = row_from_c2w_gl(&c2w, [10.0, 20.0, 30.0], 0.5, 4.0);
        let (back, hwf, n, f) = c2w_gl_from_row(&row);
        assert!(back.abs_diff_eq(c2w, 1e-12));
        assert_eq!((hwf, n, f), ([10.0, 20.0, 30.0], 0.5, 4.0));
        // First LLFF column is "down" = -up.
        assert!((row[0] + c2w.y_axis.x).abs() < 1e-12);
    }
}
