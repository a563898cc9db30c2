//! Denoising with Intel Open Image Denoise (OIDN), opened at run time.
//!
//! # Finding the library
//!
//! Like Embree (docs/embree.md), in this order:
//!
//! 1. `OIDN_DIR`: an OIDN 2 install, `$OIDN_DIR/lib{,64}/libOpenImageDenoise.so.2` or the
//!    folder itself (an error naming the variable when it holds none);
//! 2. a system `libOpenImageDenoise.so.2` (the dynamic loader's search path);
//! 3. the files of the pinned PyPI wheel `pyoidn==2.5.1.0`, which
//!    `crates/flowlight-host/oidn/fetch.py` (run by `.ci/setup`) unpacks into `target/oidn/lib`
//!    of the repository ([`FETCHED_LIB`], or `$FLOWLIGHT_OIDN_FETCH_DIR/lib`).
//!
//! Nothing links against OIDN: a renderer without it runs as before, and only `--denoise`
//! fails, with one line saying where it looked ([`Denoiser::open`]).
//!
//! # The filter
//!
//! OIDN's generic ray-tracing filter `"RT"` with `hdr = true` on the beauty (linear radiance),
//! guided by the albedo and normal AOVs ([`crate::aov`]), all three as shared float3 images;
//! the output is the layer [`LAYER`]. The beauty itself is never changed.

mod ffi;

use libloading::Library;
use std::ffi::{c_char, c_int, CStr, OsString};
use std::path::{Path, PathBuf};

/// The EXR layer of the denoised beauty.
pub const LAYER: &str = "denoised";

/// The library's SONAME.
const SONAME: &str = "libOpenImageDenoise.so.2";

/// Where `crates/flowlight-host/oidn/fetch.py` puts the wheel's library by default.
pub const FETCHED_LIB: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../target/oidn/lib/libOpenImageDenoise.so.2"
);

/// An open OIDN library and CPU device.
pub struct Denoiser {
    api: ffi::Api,
    device: ffi::Device,
    /// Where the library was found, and its version (`2.5.1`).
    pub source: String,
}

// SAFETY: an OIDN device may be used from any thread (not from two at once: `Denoiser` takes
// `&mut self` to run a filter).
unsafe impl Send for Denoiser {}

impl Drop for Denoiser {
    fn drop(&mut self) {
        // SAFETY: the device was made by this library and is released once.
        unsafe { (self.api.release_device)(self.device) }
    }
}

/// The candidates of the search (module docs) as (how it was found, path or name), for the
/// values of `OIDN_DIR` and `FLOWLIGHT_OIDN_FETCH_DIR`.
fn candidates(
    oidn_dir: Option<OsString>,
    fetch_dir: Option<OsString>,
) -> Result<Vec<(String, PathBuf)>, String> {
    if let Some(dir) = oidn_dir {
        let dir = PathBuf::from(dir);
        let found = ["lib", "lib64", "."]
            .iter()
            .map(|sub| dir.join(sub).join(SONAME))
            .find(|p| p.exists())
            .ok_or_else(|| {
                format!(
                    "--denoise: OIDN_DIR={} holds no lib/{SONAME} (nor lib64/ or the folder itself); point it at an Open Image Denoise 2 install",
                    dir.display()
                )
            })?;
        return Ok(vec![("OIDN_DIR".into(), found)]);
    }
    let fetched = fetch_dir
        .map(|d| PathBuf::from(d).join("lib").join(SONAME))
        .unwrap_or_else(|| PathBuf::from(FETCHED_LIB));
    Ok(vec![
        ("system".into(), PathBuf::from(SONAME)),
        ("pyoidn wheel".into(), fetched),
    ])
}

impl Denoiser {
    /// Opens OIDN (module docs) and commits a CPU device of `threads` threads (the render's
    /// count, so the denoiser keeps to what `--threads` allows; 0: one per core), or says in
    /// one line why not.
    pub fn open(threads: usize) -> Result<Denoiser, String> {
        Denoiser::open_from(
            std::env::var_os("OIDN_DIR"),
            std::env::var_os("FLOWLIGHT_OIDN_FETCH_DIR"),
            threads,
        )
    }

    /// [`Denoiser::open`] with these values of `OIDN_DIR` and `FLOWLIGHT_OIDN_FETCH_DIR`.
    pub fn open_from(
        oidn_dir: Option<OsString>,
        fetch_dir: Option<OsString>,
        threads: usize,
    ) -> Result<Denoiser, String> {
        let mut tried = Vec::new();
        for (how, path) in candidates(oidn_dir, fetch_dir)? {
            // SAFETY: loading runs the library's initialisers; OIDN's only set up its own
            // state. The path is an OIDN library by name.
            match unsafe { Library::new(&path) } {
                Ok(lib) => return Denoiser::with_library(lib, &how, &path, threads),
                Err(e) => {
                    // libloading's message is "dlopen failed"; the loader's reason is its source.
                    let why =
                        std::error::Error::source(&e).map_or(e.to_string(), |s| s.to_string());
                    tried.push(format!("{how} {}: {why}", path.display()));
                }
            }
        }
        Err(format!(
            "--denoise needs Intel Open Image Denoise 2, which was not found: set OIDN_DIR to an install holding lib/{SONAME}, install it system-wide, or run python3 crates/flowlight-host/oidn/fetch.py (tried: {})",
            tried.join("; ")
        ))
    }

    fn with_library(
        lib: Library,
        how: &str,
        path: &Path,
        threads: usize,
    ) -> Result<Denoiser, String> {
        let at = |e: String| format!("--denoise: {} ({how}): {e}", path.display());
        // SAFETY: the library is found under OIDN's SONAME.
        let api = unsafe { ffi::Api::resolve(lib) }.map_err(at)?;
        // SAFETY: the C API's calls, with a device this library made.
        let device = unsafe { (api.new_device)(ffi::DEVICE_TYPE_CPU) };
        if device.is_null() {
            return Err(at("oidnNewDevice returned no CPU device".into()));
        }
        let mut d = Denoiser {
            api,
            device,
            source: String::new(),
        };
        // OIDN starts its own worker threads (TBB), all cores unless told: the render's count.
        let threads = c_int::try_from(threads).unwrap_or(c_int::MAX);
        // SAFETY: as above; a device parameter set by its documented name before the commit.
        unsafe {
            (d.api.set_device_int)(d.device, c"numThreads".as_ptr(), threads);
            (d.api.commit_device)(d.device);
        }
        d.check().map_err(at)?;
        let int = |name: &CStr| {
            // SAFETY: a device parameter read by its documented name.
            unsafe { (d.api.get_device_int)(d.device, name.as_ptr()) }
        };
        let version = int(c"version");
        d.source = format!(
            "Open Image Denoise {}.{}.{} ({how}: {})",
            version / 10000,
            version / 100 % 100,
            version % 100,
            path.canonicalize().as_deref().unwrap_or(path).display()
        );
        Ok(d)
    }

    /// The device's pending error, as one line.
    fn check(&self) -> Result<(), String> {
        let mut msg: *const c_char = std::ptr::null();
        // SAFETY: OIDN writes a pointer to its own NUL-terminated message, valid until the
        // next call on the device.
        let code = unsafe { (self.api.get_device_error)(self.device, &mut msg) };
        if code == ffi::ERROR_NONE {
            return Ok(());
        }
        let text = if msg.is_null() {
            String::new()
        } else {
            // SAFETY: as above.
            unsafe { CStr::from_ptr(msg) }
                .to_string_lossy()
                .into_owned()
        };
        Err(format!("Open Image Denoise error {code}: {}", text.trim()))
    }

    /// Denoises `color` (linear radiance, HDR) of a `width` × `height` image with the
    /// `albedo` and `normal` guides, all interleaved RGB (`width · height · 3` floats):
    /// the denoised image, interleaved the same way.
    pub fn denoise(
        &mut self,
        width: usize,
        height: usize,
        color: &[f32],
        albedo: &[f32],
        normal: &[f32],
    ) -> Result<Vec<f32>, String> {
        let n = width * height * 3;
        if [color.len(), albedo.len(), normal.len()] != [n; 3] {
            return Err(format!(
                "--denoise: the images must hold {n} floats ({width}x{height} RGB)"
            ));
        }
        // OIDN reads the inputs through `void*`; it writes only the output.
        let mut inputs = [color.to_vec(), albedo.to_vec(), normal.to_vec()];
        let mut output = vec![0.0f32; n];
        let api = &self.api;
        // SAFETY: the C API's calls on a filter of this device; every image is a live
        // buffer of width · height float3 pixels, densely packed (strides 0: computed by
        // OIDN), that outlives the filter's execution.
        unsafe {
            let filter = (api.new_filter)(self.device, c"RT".as_ptr());
            if filter.is_null() {
                return Err(format!(
                    "--denoise: {}",
                    self.check().err().unwrap_or_default()
                ));
            }
            let images: [(&CStr, *mut f32); 4] = [
                (c"color", inputs[0].as_mut_ptr()),
                (c"albedo", inputs[1].as_mut_ptr()),
                (c"normal", inputs[2].as_mut_ptr()),
                (c"output", output.as_mut_ptr()),
            ];
            for (name, ptr) in images {
                (api.set_shared_filter_image)(
                    filter,
                    name.as_ptr(),
                    ptr.cast(),
                    ffi::FORMAT_FLOAT3,
                    width,
                    height,
                    0,
                    0,
                    0,
                );
            }
            (api.set_filter_bool)(filter, c"hdr".as_ptr(), true);
            (api.commit_filter)(filter);
            let committed = self.check();
            if committed.is_ok() {
                (api.execute_filter)(filter);
            }
            let executed = committed.and_then(|_| self.check());
            (api.release_filter)(filter);
            executed.map_err(|e| format!("--denoise: {e}"))?;
        }
        drop(inputs);
        Ok(output)
    }
}

/// Denoises a render's beauty `image` with its AOV pass's albedo and normal (which must be
/// in `aovs`): the `denoised` layer, planar.
pub fn denoise_image(
    denoiser: &mut Denoiser,
    image: &[flowlight_core::Rgb],
    aovs: &crate::aov::AovImages,
) -> Result<[Vec<f32>; 3], String> {
    use flowlight_scene::config::Aov;
    let guide = |a: Aov| {
        aovs.layer(a)
            .map(interleave)
            .ok_or_else(|| format!("--denoise: the AOV pass has no {} layer", a.name()))
    };
    let (albedo, normal) = (guide(Aov::Albedo)?, guide(Aov::Normal)?);
    let color: Vec<f32> = image.iter().flat_map(|c| c.to_array()).collect();
    let out = denoiser.denoise(
        aovs.width as usize,
        aovs.height as usize,
        &color,
        &albedo,
        &normal,
    )?;
    Ok(planar(&out))
}

/// Interleaves planar channels (r, g, b) into RGB triples.
pub fn interleave(channels: &[Vec<f32>; 3]) -> Vec<f32> {
    (0..channels[0].len())
        .flat_map(|i| [channels[0][i], channels[1][i], channels[2][i]])
        .collect()
}

/// Splits RGB triples into planar channels (r, g, b), non-finite values replaced by 0.
pub fn planar(rgb: &[f32]) -> [Vec<f32>; 3] {
    std::array::from_fn(|c| {
        rgb.chunks_exact(3)
            .map(|p| if p[c].is_finite() { p[c] } else { 0.0 })
            .collect()
    })
}

#[cfg(test)]
mod tests;
