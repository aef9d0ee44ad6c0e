//! Task events of compiled plugins: the host side of [`abi::EventDecl`], as engine events
//! ([`crate::events`]).

use std::ffi::c_void;
use std::sync::Arc;

use modesuite_plugin_abi as abi;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use super::call::{status, Text, UserPtr};
use crate::events::{ConfiguredEvent, EventFactory, EventWorld};

type EventConfigureFn =
    extern "C" fn(*const c_void, abi::AbiStr, *mut u32, *const abi::TextSink) -> i32;
type EventApplyFn = extern "C" fn(*const c_void, *const abi::EventCall) -> i32;

/// A task event of a compiled plugin.
pub(super) struct DynEvent {
    pub(super) plugin: String,
    pub(super) user: UserPtr,
    pub(super) configure: EventConfigureFn,
    pub(super) apply: EventApplyFn,
}

/// A plugin event with its parameters.
struct DynConfiguredEvent {
    event: Arc<DynEvent>,
    params: String,
    interval_safe: bool,
}

impl EventFactory for Arc<DynEvent> {
    fn configure(&self, params_ron: &str) -> Result<Arc<dyn ConfiguredEvent>, String> {
        let mut text = Text(String::new());
        let error = text.sink();
        let mut safe = 0u32;
        let code = (self.configure)(self.user.0, abi::AbiStr::new(params_ron), &mut safe, &error);
        status(&self.plugin, "configure", code, text)?;
        Ok(Arc::new(DynConfiguredEvent {
            event: self.clone(),
            params: params_ron.to_string(),
            interval_safe: safe != 0,
        }))
    }
}

impl ConfiguredEvent for DynConfiguredEvent {
    fn interval_safe(&self) -> bool {
        self.interval_safe
    }

    fn apply(&self, name: &str, world: &mut dyn EventWorld) -> Result<(), String> {
        let mut host_ctx = HostCtx { world };
        let host = abi::EventHost {
            ctx: (&mut host_ctx as *mut HostCtx).cast(),
            uniform: host_uniform,
            push: host_push,
            move_object: host_move,
            set_friction: host_friction,
        };
        let mut text = Text(String::new());
        let call = abi::EventCall {
            params: abi::AbiStr::new(&self.params),
            name: abi::AbiStr::new(name),
            host: &host,
            error: text.sink(),
        };
        let code = (self.event.apply)(self.event.user.0, &call);
        status(&self.event.plugin, "apply", code, text)
    }
}

/// What the host functions reach during one `apply` call.
struct HostCtx<'a, 'w> {
    world: &'a mut (dyn EventWorld + 'w),
}

/// The world of a host call.
///
/// # Safety
/// `ctx` must be the `HostCtx` that [`DynConfiguredEvent::apply`] passed for this call.
unsafe fn host<'a>(ctx: *mut c_void) -> &'a mut HostCtx<'a, 'a> {
    // SAFETY: guaranteed by the caller.
    unsafe { &mut *ctx.cast::<HostCtx>() }
}

/// Runs a host function's body: its error goes to the plugin's sink as [`abi::STATUS_ERROR`].
fn report(error: *const abi::TextSink, r: Result<(), String>) -> i32 {
    match r {
        Ok(()) => abi::STATUS_OK,
        Err(message) => {
            if !error.is_null() {
                // SAFETY: a non-null sink comes from the plugin and is valid during the call.
                let sink = unsafe { &*error };
                (sink.write)(sink.ctx, abi::AbiStr::new(&message));
            }
            abi::STATUS_ERROR
        }
    }
}

fn object_name<'a>(object: abi::AbiStr) -> Result<&'a str, String> {
    if object.len > 0 && object.ptr.is_null() {
        return Err("object name: null pointer".into());
    }
    // SAFETY: the plugin passes a string valid during the call.
    unsafe { object.as_str() }.map_err(|e| format!("object name: not UTF-8 ({e})"))
}

/// Reads `n` f64 from a plugin pointer (valid during the call).
fn values<const N: usize>(ptr: *const f64, what: &str) -> Result<[f64; N], String> {
    if ptr.is_null() {
        return Err(format!("{what}: null pointer"));
    }
    // SAFETY: the ABI says the plugin passes `N` readable f64 at `ptr` during the call.
    let v = unsafe { std::slice::from_raw_parts(ptr, N) };
    let out: [f64; N] = v.try_into().map_err(|_| format!("{what}: {N} values"))?;
    if out.iter().all(|x| x.is_finite()) {
        Ok(out)
    } else {
        Err(format!("{what} = {out:?}: finite values"))
    }
}

extern "C" fn host_uniform(ctx: *mut c_void, lo: f64, hi: f64) -> f64 {
    // SAFETY: the plugin passes back the context of this call.
    let h = unsafe { host(ctx) };
    h.world.uniform(lo, hi)
}

extern "C" fn host_push(
    ctx: *mut c_void,
    object: abi::AbiStr,
    dv: *const f64,
    error: *const abi::TextSink,
) -> i32 {
    // SAFETY: the plugin passes back the context of this call.
    let h = unsafe { host(ctx) };
    let r = object_name(object).and_then(|o| {
        let [x, y, z] = values::<3>(dv, "push velocity")?;
        h.world.push(o, Vector3::new(x, y, z))
    });
    report(error, r)
}

extern "C" fn host_move(
    ctx: *mut c_void,
    object: abi::AbiStr,
    pose: *const f64,
    error: *const abi::TextSink,
) -> i32 {
    // SAFETY: the plugin passes back the context of this call.
    let h = unsafe { host(ctx) };
    let r = object_name(object).and_then(|o| {
        let [x, y, z, qx, qy, qz, qw] = values::<7>(pose, "pose")?;
        let q = Quaternion::new(qw, qx, qy, qz);
        if (q.norm() - 1.0).abs() > 1e-6 {
            return Err(format!(
                "pose rotation ({qx}, {qy}, {qz}, {qw}): a unit quaternion (x, y, z, w)"
            ));
        }
        let iso =
            Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::new_normalize(q));
        h.world.move_object(o, &iso)
    });
    report(error, r)
}

extern "C" fn host_friction(
    ctx: *mut c_void,
    object: abi::AbiStr,
    friction: f64,
    error: *const abi::TextSink,
) -> i32 {
    // SAFETY: the plugin passes back the context of this call.
    let h = unsafe { host(ctx) };
    let r = object_name(object).and_then(|o| h.world.set_friction(o, friction));
    report(error, r)
}
