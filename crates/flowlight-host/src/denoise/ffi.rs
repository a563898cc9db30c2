//! The few entry points of the Open Image Denoise 2 C API (`OpenImageDenoise/oidn.h`) that
//! the denoiser calls, resolved by name from the library opened at run time.

use libloading::Library;
use std::ffi::{c_char, c_int, c_void};

pub type Device = *mut c_void;
pub type Filter = *mut c_void;

/// `OIDN_DEVICE_TYPE_CPU`.
pub const DEVICE_TYPE_CPU: c_int = 1;
/// `OIDN_FORMAT_FLOAT3`.
pub const FORMAT_FLOAT3: c_int = 3;
/// `OIDN_ERROR_NONE`.
pub const ERROR_NONE: c_int = 0;

/// The entry points, kept with the library that holds them.
pub struct Api {
    pub new_device: unsafe extern "C" fn(c_int) -> Device,
    pub commit_device: unsafe extern "C" fn(Device),
    pub release_device: unsafe extern "C" fn(Device),
    pub get_device_error: unsafe extern "C" fn(Device, *mut *const c_char) -> c_int,
    pub get_device_int: unsafe extern "C" fn(Device, *const c_char) -> c_int,
    pub set_device_int: unsafe extern "C" fn(Device, *const c_char, c_int),
    pub new_filter: unsafe extern "C" fn(Device, *const c_char) -> Filter,
    #[allow(clippy::type_complexity)]
    pub set_shared_filter_image: unsafe extern "C" fn(
        Filter,
        *const c_char,
        *mut c_void,
        c_int,
        usize,
        usize,
        usize,
        usize,
        usize,
    ),
    pub set_filter_bool: unsafe extern "C" fn(Filter, *const c_char, bool),
    pub commit_filter: unsafe extern "C" fn(Filter),
    pub execute_filter: unsafe extern "C" fn(Filter),
    pub release_filter: unsafe extern "C" fn(Filter),
    /// Keeps the functions above valid.
    _lib: Library,
}

impl Api {
    /// Resolves the entry points of `lib`, or names the first one missing.
    ///
    /// # Safety
    /// `lib` must be an Open Image Denoise 2 library: the symbols are taken to have the C
    /// API's signatures.
    pub unsafe fn resolve(lib: Library) -> Result<Api, String> {
        macro_rules! sym {
            ($name:literal) => {
                // SAFETY: the caller vouches that `lib` is OIDN 2, whose symbol of this name
                // has the signature of the field it is stored in.
                *unsafe { lib.get(concat!($name, "\0").as_bytes()) }
                    .map_err(|e| format!("the library has no {}: {e}", $name))?
            };
        }
        Ok(Api {
            new_device: sym!("oidnNewDevice"),
            commit_device: sym!("oidnCommitDevice"),
            release_device: sym!("oidnReleaseDevice"),
            get_device_error: sym!("oidnGetDeviceError"),
            get_device_int: sym!("oidnGetDeviceInt"),
            set_device_int: sym!("oidnSetDeviceInt"),
            new_filter: sym!("oidnNewFilter"),
            set_shared_filter_image: sym!("oidnSetSharedFilterImage"),
            set_filter_bool: sym!("oidnSetFilterBool"),
            commit_filter: sym!("oidnCommitFilter"),
            execute_filter: sym!("oidnExecuteFilter"),
            release_filter: sym!("oidnReleaseFilter"),
            _lib: lib,
        })
    }
}
