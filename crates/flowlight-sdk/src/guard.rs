//! Keeps errors and panics on the plugin's side of the boundary.

use crate::abi::{ErrorBuf, Status};
use std::panic::{catch_unwind, AssertUnwindSafe};

use std::cell::{Cell, RefCell};
use std::sync::Once;

thread_local! {
    /// Set while `guard` runs a call on this thread: its panics are reported through the
    /// error buffer, not printed.
    static GUARDED: Cell<bool> = const { Cell::new(false) };
    /// Where the last guarded panic happened.
    static LOCATION: RefCell<Option<String>> = const { RefCell::new(None) };
}

/// Installs, once, a panic hook that keeps guarded panics quiet (the host prints the one
/// line the error buffer carries) and passes every other panic to the previous hook.
fn quiet_guarded_panics() {
    static HOOK: Once = Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if GUARDED.with(Cell::get) {
                let at = info
                    .location()
                    .map(|l| format!("{}:{}:{}", l.file(), l.line(), l.column()));
                LOCATION.with(|c| *c.borrow_mut() = at);
            } else {
                previous(info);
            }
        }));
    });
}

/// Runs `f`, copying an error or a caught panic's message (with its source location) into
/// `err`. A panic inside `f` prints nothing itself.
///
/// # Safety
/// `err` must be null or point to a valid [`ErrorBuf`].
pub unsafe fn guard(err: *mut ErrorBuf, f: impl FnOnce() -> Result<(), String>) -> Status {
    // SAFETY: the caller upholds this function's contract (its `# Safety` section, or the
    // ABI rules in `abi.rs` for the C entry points).
    unsafe {
        quiet_guarded_panics();
        let outer = GUARDED.with(|g| g.replace(true));
        let result = catch_unwind(AssertUnwindSafe(f));
        GUARDED.with(|g| g.set(outer));
        match result {
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
                let at = LOCATION
                    .with(|c| c.borrow_mut().take())
                    .map(|l| format!(" at {l}"))
                    .unwrap_or_default();
                if let Some(e) = err.as_mut() {
                    e.set(&format!("panicked: {msg}{at}").replace('\n', " "));
                }
                Status::Panic
            }
        }
    }
}
