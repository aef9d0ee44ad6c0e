//! The host side of a call into a plugin: the context pointer handed back to it, the text buffer
//! it writes messages into, and status codes turned into results.

use std::ffi::c_void;

use modesuite_plugin_abi as abi;

/// A plugin context pointer (the `user` field of a declaration).
#[derive(Clone, Copy)]
pub(super) struct UserPtr(pub(super) *const c_void);

// SAFETY: the ABI requires plugin callbacks to be callable from any thread, concurrently (one
// env per thread); the pointer itself is only passed back to the plugin, never dereferenced here.
unsafe impl Send for UserPtr {}
// SAFETY: as above.
unsafe impl Sync for UserPtr {}

/// A host-side text buffer handed to the plugin as a [`abi::TextSink`].
pub(super) struct Text(pub(super) String);

extern "C" fn write_text(ctx: *mut c_void, text: abi::AbiStr) {
    if ctx.is_null() || (text.len > 0 && text.ptr.is_null()) {
        return;
    }
    // SAFETY: `ctx` is the `Text` this module passed for the duration of the call.
    let buf = unsafe { &mut *ctx.cast::<Text>() };
    let bytes = if text.len == 0 {
        &[][..]
    } else {
        // SAFETY: the plugin passes `len` readable bytes, valid during this call.
        unsafe { std::slice::from_raw_parts(text.ptr, text.len) }
    };
    buf.0.push_str(&String::from_utf8_lossy(bytes));
}

impl Text {
    pub(super) fn sink(&mut self) -> abi::TextSink {
        abi::TextSink {
            ctx: (self as *mut Text).cast(),
            write: write_text,
        }
    }
}

/// Turns a status code and the error text into a result; `what` names the call.
pub(super) fn status(plugin: &str, what: &str, code: i32, text: Text) -> Result<(), String> {
    let message = if text.0.is_empty() {
        "(no message)".to_string()
    } else {
        text.0
    };
    match code {
        abi::STATUS_OK => Ok(()),
        abi::STATUS_ERROR => Err(message),
        abi::STATUS_PANIC => Err(format!("plugin \"{plugin}\" {what}: {message}")),
        other => Err(format!(
            "plugin \"{plugin}\" {what}: unknown status {other} ({message})"
        )),
    }
}
