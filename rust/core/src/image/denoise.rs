//! Denoising a finished linear image with Intel Open Image Denoise (OIDN), the denoiser
//! Cycles itself uses (issue 28, DESIGN §8).
//!
//! A blurry image is denoised once, after averaging: the accumulator averages its latent
//! frames' colour and their guide passes (Cycles' "Denoising Albedo" and "Denoising
//! Normal") the same way, and the denoiser sees the mean. The sharp image goes through
//! the same call, so a pair stays a pair.
//!
//! The library is loaded at run time from a path the caller gives (the `bpy` wheel ships
//! `libOpenImageDenoise.so.2` beside Cycles): no build-time dependency, and the OIDN that
//! denoises is the one the pinned Blender renders with. The call follows Cycles'
//! defaults (`denoising_prefilter = ACCURATE`, `denoising_quality = HIGH`, input passes
//! colour + albedo + normal): the albedo and normal means are prefiltered by their own
//! `RT` filter first, then the colour is filtered with `cleanAux` and `hdr` on. Alpha is
//! not denoised (Cycles leaves it as rendered). Images go through OIDN buffers, so the
//! same code runs on a GPU device when OIDN finds one (`DenoiseDevice::Auto`).
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::ffi::{c_char, c_void, CStr, CString};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

type Device = *mut c_void;
type Filter = *mut c_void;
type Buffer = *mut c_void;

// OIDN 2 C API constants (OpenImageDenoise/oidn.h).
const DEVICE_TYPE_DEFAULT: i32 = 0;
const DEVICE_TYPE_CPU: i32 = 1;
const FORMAT_FLOAT3: i32 = 3;
const QUALITY_HIGH: i32 = 6;

/// Which OIDN device denoises.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DenoiseDevice {
    /// OIDN's choice: the fastest device it supports (a GPU when one is there).
    Auto,
    Cpu,
}

struct Api {
    new_device: unsafe extern "C" fn(i32) -> Device,
    commit_device: unsafe extern "C" fn(Device),
    release_device: unsafe extern "C" fn(Device),
    get_device_error: unsafe extern "C" fn(Device, *mut *const c_char) -> i32,
    get_device_int: unsafe extern "C" fn(Device, *const c_char) -> i32,
    new_buffer: unsafe extern "C" fn(Device, usize) -> Buffer,
    release_buffer: unsafe extern "C" fn(Buffer),
    write_buffer: unsafe extern "C" fn(Buffer, usize, usize, *const c_void),
    read_buffer: unsafe extern "C" fn(Buffer, usize, usize, *mut c_void),
    new_filter: unsafe extern "C" fn(Device, *const c_char) -> Filter,
    release_filter: unsafe extern "C" fn(Filter),
    set_filter_image:
        unsafe extern "C" fn(Filter, *const c_char, Buffer, i32, usize, usize, usize, usize, usize),
    set_filter_bool: unsafe extern "C" fn(Filter, *const c_char, bool),
    set_filter_int: unsafe extern "C" fn(Filter, *const c_char, i32),
    commit_filter: unsafe extern "C" fn(Filter),
    execute_filter: unsafe extern "C" fn(Filter),
}

/// An open OIDN library and one committed device. Calls are serialized (one image at a
/// time); OIDN spreads each over every core (CPU) or runs it on the GPU.
pub struct Denoiser {
    // Keeps the library mapped while `api` points into it.
    _lib: libloading::Library,
    api: Api,
    device: Mutex<DevicePtr>,
    path: PathBuf,
    /// OIDN's version (major · 10000 + minor · 100 + patch) and device type name.
    version: i32,
    device_type: &'static str,
}

struct DevicePtr(Device);
// SAFETY: an OIDN device may be used from any thread; the mutex serializes the calls.
unsafe impl Send for DevicePtr {}

/// Owns an OIDN object and releases it on every path out of `run`.
struct Owned<T: Copy>(T, unsafe extern "C" fn(T));
impl<T: Copy> Drop for Owned<T> {
    fn drop(&mut self) {
        // SAFETY: the handle came from the matching oidnNew* call and is released once.
        unsafe { (self.1)(self.0) }
    }
}

fn cstr(s: &str) -> CString {
    // Names are literals of this file: no interior NUL.
    CString::new(s).unwrap_or_default()
}

impl Denoiser {
    /// Load OIDN from `library` (a path to `libOpenImageDenoise.so.2` or its platform's
    /// name) and commit a device; the error names the file and what OIDN said.
    pub fn open(library: &Path, device: DenoiseDevice) -> Result<Denoiser> {
        let bad = |reason: String| Error::Input {
            reason,
            path: library.to_path_buf(),
        };
        // SAFETY: loading OIDN runs its initializers only (C++ static constructors).
        let lib = unsafe { libloading::Library::new(library) }
            .map_err(|e| bad(format!("cannot load Open Image Denoise ({e})")))?;
        let api = load_api(&lib).map_err(bad)?;
        let (dev, version, ty) = commit_device(&api, device).map_err(bad)?;
        Ok(Denoiser {
            _lib: lib,
            api,
            device: Mutex::new(DevicePtr(dev)),
            path: library.to_path_buf(),
            version,
            device_type: device_type_name(ty),
        })
    }

    /// The library file this denoiser loaded.
    pub fn library(&self) -> &Path {
        &self.path
    }

    /// OIDN's version as text (`2.3.3`).
    pub fn version(&self) -> String {
        let v = self.version;
        format!("{}.{}.{}", v / 10000, v / 100 % 100, v % 100)
    }

    /// The device type OIDN runs on: CPU, CUDA, HIP, SYCL or METAL.
    pub fn device_type(&self) -> &'static str {
        self.device_type
    }

    /// What meta.json records of this denoiser.
    pub fn record(&self) -> DenoiserRecord {
        DenoiserRecord {
            device: self.device_type.into(),
            library: "OpenImageDenoise".into(),
            version: self.version(),
        }
    }

    /// Denoise a `width × height` colour image (3 f32 per pixel, scene-linear) with its
    /// albedo and normal guides (3 f32 per pixel each); returns the denoised colour.
    pub fn denoise(
        &self,
        width: u32,
        height: u32,
        color: &[f32],
        albedo: &[f32],
        normal: &[f32],
    ) -> Result<Vec<f32>> {
        let (w, h) = (width as usize, height as usize);
        let n = w * h * 3;
        for (what, v) in [("colour", color), ("albedo", albedo), ("normal", normal)] {
            if v.len() != n {
                return Err(Error::Shape(format!(
                    "denoise: {what} has {} values, a {width}x{height} RGB image needs {n}",
                    v.len()
                )));
            }
        }
        if n == 0 {
            return Ok(Vec::new());
        }
        let guard = self.device.lock().map_err(|_| poisoned())?;
        let call = Call {
            api: &self.api,
            dev: guard.0,
            w,
            h,
            bytes: n * 4,
        };
        let mut out = vec![0.0f32; n];
        // SAFETY: a committed device, locked for the call; every slice holds n values.
        unsafe { call.run(color, albedo, normal, &mut out)? };
        drop(guard);
        if let Some(i) = out.iter().position(|v| !v.is_finite()) {
            return Err(Error::Value(format!(
                "OIDN returned a non-finite value {} at pixel ({}, {})",
                out[i],
                (i / 3) % w,
                i / 3 / w
            )));
        }
        Ok(out)
    }
}

/// The OIDN 2 functions blurset calls, looked up in `lib` by name.
fn load_api(lib: &libloading::Library) -> std::result::Result<Api, String> {
    macro_rules! sym {
        ($name:literal) => {
            // SAFETY: the symbol is OIDN 2's function of this name and signature.
            *unsafe { lib.get(concat!($name, "\0").as_bytes()) }
                .map_err(|e| format!("not an OIDN 2 library: no {} ({e})", $name))?
        };
    }
    Ok(Api {
        new_device: sym!("oidnNewDevice"),
        commit_device: sym!("oidnCommitDevice"),
        release_device: sym!("oidnReleaseDevice"),
        get_device_error: sym!("oidnGetDeviceError"),
        get_device_int: sym!("oidnGetDeviceInt"),
        new_buffer: sym!("oidnNewBuffer"),
        release_buffer: sym!("oidnReleaseBuffer"),
        write_buffer: sym!("oidnWriteBuffer"),
        read_buffer: sym!("oidnReadBuffer"),
        new_filter: sym!("oidnNewFilter"),
        release_filter: sym!("oidnReleaseFilter"),
        set_filter_image: sym!("oidnSetFilterImage"),
        set_filter_bool: sym!("oidnSetFilterBool"),
        set_filter_int: sym!("oidnSetFilterInt"),
        commit_filter: sym!("oidnCommitFilter"),
        execute_filter: sym!("oidnExecuteFilter"),
    })
}

/// A new committed device of the kind asked for, with OIDN's version and device type
/// number.
fn commit_device(
    api: &Api,
    device: DenoiseDevice,
) -> std::result::Result<(Device, i32, i32), String> {
    let kind = match device {
        DenoiseDevice::Auto => DEVICE_TYPE_DEFAULT,
        DenoiseDevice::Cpu => DEVICE_TYPE_CPU,
    };
    // SAFETY: OIDN C API calls with valid arguments; errors are read back below.
    let dev = unsafe { (api.new_device)(kind) };
    if dev.is_null() {
        return Err("no OIDN device could be created".into());
    }
    // SAFETY: as above; the device is released if it failed to commit.
    unsafe {
        (api.commit_device)(dev);
        if let Err(e) = device_error(api, dev) {
            (api.release_device)(dev);
            return Err(e.to_string());
        }
        Ok((
            dev,
            (api.get_device_int)(dev, cstr("version").as_ptr()),
            (api.get_device_int)(dev, cstr("type").as_ptr()),
        ))
    }
}

/// OIDN's name of its device type number (`OIDNDeviceType`).
fn device_type_name(ty: i32) -> &'static str {
    match ty {
        1 => "CPU",
        2 => "SYCL",
        3 => "CUDA",
        4 => "HIP",
        5 => "METAL",
        _ => "unknown",
    }
}

/// One denoise on a locked device: OIDN buffers of `bytes` bytes, images of w × h
/// FLOAT3 pixels packed (strides 0 = packed). Every handle is released by its `Owned`
/// guard, on every path out.
struct Call<'a> {
    api: &'a Api,
    dev: Device,
    w: usize,
    h: usize,
    bytes: usize,
}

impl Call<'_> {
    /// Colour, then guides prefiltered in place, then the colour filtered into `out`.
    ///
    /// SAFETY: `dev` is a committed device no other thread uses meanwhile; every slice
    /// holds `bytes` bytes.
    unsafe fn run(
        &self,
        color: &[f32],
        albedo: &[f32],
        normal: &[f32],
        out: &mut [f32],
    ) -> Result<()> {
        let (api, dev) = (self.api, self.dev);
        let bc = self.buffer(color)?;
        let ba = self.buffer(albedo)?;
        let bn = self.buffer(normal)?;
        let bo = self.buffer(out)?;
        // Prefilter the guides in place (Cycles' ACCURATE prefilter): an RT filter
        // given only an auxiliary image denoises that image.
        for (name, b) in [("albedo", &ba), ("normal", &bn)] {
            let f = self.rt_filter()?;
            self.image(f.0, name, b.0);
            self.image(f.0, "output", b.0);
            (api.commit_filter)(f.0);
            (api.execute_filter)(f.0);
            drop(f);
            device_error(api, dev)?;
        }
        let f = self.rt_filter()?;
        self.image(f.0, "color", bc.0);
        self.image(f.0, "albedo", ba.0);
        self.image(f.0, "normal", bn.0);
        self.image(f.0, "output", bo.0);
        (api.set_filter_bool)(f.0, cstr("hdr").as_ptr(), true);
        (api.set_filter_bool)(f.0, cstr("cleanAux").as_ptr(), true);
        (api.commit_filter)(f.0);
        (api.execute_filter)(f.0);
        device_error(api, dev)?;
        (api.read_buffer)(bo.0, 0, self.bytes, out.as_mut_ptr().cast());
        device_error(api, dev)
    }

    /// A device buffer holding a copy of `data`.
    ///
    /// SAFETY: as [`Call::run`].
    unsafe fn buffer(&self, data: &[f32]) -> Result<Owned<Buffer>> {
        let b = (self.api.new_buffer)(self.dev, self.bytes);
        if b.is_null() {
            return Err(Error::Value(format!(
                "OIDN could not allocate {} bytes",
                self.bytes
            )));
        }
        (self.api.write_buffer)(b, 0, self.bytes, data.as_ptr().cast());
        Ok(Owned(b, self.api.release_buffer))
    }

    /// A new `RT` filter at Cycles' `HIGH` quality.
    ///
    /// SAFETY: as [`Call::run`].
    unsafe fn rt_filter(&self) -> Result<Owned<Filter>> {
        let f = (self.api.new_filter)(self.dev, cstr("RT").as_ptr());
        if f.is_null() {
            return Err(Error::Value("OIDN has no RT filter".into()));
        }
        (self.api.set_filter_int)(f, cstr("quality").as_ptr(), QUALITY_HIGH);
        Ok(Owned(f, self.api.release_filter))
    }

    /// Set the filter's image `name` to the buffer `b`.
    ///
    /// SAFETY: as [`Call::run`]; `f` and `b` are live handles of this call.
    unsafe fn image(&self, f: Filter, name: &str, b: Buffer) {
        let (w, h) = (self.w, self.h);
        (self.api.set_filter_image)(f, cstr(name).as_ptr(), b, FORMAT_FLOAT3, w, h, 0, 0, 0)
    }
}

/// The device's pending error (and clear it), as an error naming OIDN's message.
fn device_error(api: &Api, dev: Device) -> Result<()> {
    let mut msg: *const c_char = std::ptr::null();
    // SAFETY: a valid device; OIDN owns the message until the next call.
    let code = unsafe { (api.get_device_error)(dev, &mut msg) };
    if code == 0 {
        return Ok(());
    }
    let text = if msg.is_null() {
        String::new()
    } else {
        // SAFETY: OIDN returns a NUL-terminated string.
        unsafe { CStr::from_ptr(msg) }
            .to_string_lossy()
            .into_owned()
    };
    Err(Error::Value(format!("OIDN error {code}: {text}")))
}

fn poisoned() -> Error {
    Error::Value("the denoiser's lock was poisoned by a panic".into())
}

impl Drop for Denoiser {
    fn drop(&mut self) {
        if let Ok(d) = self.device.get_mut() {
            // SAFETY: the device was created by oidnNewDevice and is released once.
            unsafe { (self.api.release_device)(d.0) }
        }
    }
}

impl std::fmt::Debug for Denoiser {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Denoiser(OIDN {} on {}, {:?})",
            self.version(),
            self.device_type,
            self.path
        )
    }
}

/// The denoiser of a build's images, as meta.json records it (fields in alphabetical
/// order, as the dict it replaced was written).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DenoiserRecord {
    /// The device type OIDN ran on: CPU, CUDA, HIP, SYCL or METAL.
    pub device: String,
    /// `OpenImageDenoise`.
    pub library: String,
    /// Its version, e.g. 2.3.3.
    pub version: String,
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
pub(crate) mod tests {
    use super::*;

    /// The OIDN of the venv's bpy wheel, when the tests run beside one.
    pub(crate) fn library() -> Option<PathBuf> {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let venv = root.join(".venv/lib");
        for py in std::fs::read_dir(venv).ok()?.flatten() {
            let p = py
                .path()
                .join("site-packages/bpy/lib/libOpenImageDenoise.so.2");
            if p.exists() {
                return Some(p);
            }
        }
        None
    }

    #[test]
    fn a_missing_library_is_one_clear_error() {
        let e = Denoiser::open(Path::new("/nonexistent/libOIDN.so"), DenoiseDevice::Cpu)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("cannot load Open Image Denoise") && e.contains("libOIDN.so"),
            "{e}"
        );
    }

    #[test]
    fn denoising_flattens_noise_and_keeps_a_flat_image() -> Result<()> {
        let Some(lib) = library() else {
            eprintln!("no bpy wheel with OIDN beside the repo: skipped");
            return Ok(());
        };
        let d = Denoiser::open(&lib, DenoiseDevice::Cpu)?;
        assert_eq!(d.device_type(), "CPU");
        assert!(d.version().starts_with('2'), "{}", d.version());
        let (w, h) = (32u32, 24u32);
        let n = (w * h * 3) as usize;
        let mut s = crate::rng::Stream::new(7, 0);
        let noisy: Vec<f32> = (0..n)
            .map(|_| 0.5 + 0.1 * (s.uniform() as f32 - 0.5))
            .collect();
        let albedo = vec![0.8f32; n];
        let normal: Vec<f32> = (0..n).map(|i| if i % 3 == 2 { 1.0 } else { 0.0 }).collect();
        let out = d.denoise(w, h, &noisy, &albedo, &normal)?;
        let var = |v: &[f32]| {
            let m = v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64;
            v.iter().map(|&x| (f64::from(x) - m).powi(2)).sum::<f64>() / v.len() as f64
        };
        assert!(
            var(&out) < var(&noisy) / 4.0,
            "{} {}",
            var(&out),
            var(&noisy)
        );
        let mean = out.iter().map(|&x| f64::from(x)).sum::<f64>() / n as f64;
        assert!((mean - 0.5).abs() < 0.02, "{mean}");
        let e = d.denoise(w, h, &noisy[1..], &albedo, &normal).unwrap_err();
        assert!(e.to_string().contains("colour"), "{e}");
        Ok(())
    }
}
