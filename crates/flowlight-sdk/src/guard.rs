//! Keeps errors and panics on the plugin's side of the boundary.

use crate::abi::{ErrorBuf, Status};
use std::panic::{catch_unwind, AssertUnwindSafe};

/// Runs `f`, copying an error or a caught panic's message into `err`.
///
/// # Safety
/// `err` must be null or point to a valid [`ErrorBuf`].
pub unsafe fn guard(err: *mut ErrorBuf, f: impl FnOnce() -> Result<(), String>) -> Status {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(())) => Status::Ok,
        Ok(Err(msg)) => {
            if let Some(e) = err.as_mut() {
                e.set(&msg);
            }
            Status::Error
        }
        Err(payload) => {
            let msg = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic payload".into());
            if let Some(e) = err.as_mut() {
                e.set(&format!("panicked: {msg}"));
            }
            Status::Panic
        }
    }
}
