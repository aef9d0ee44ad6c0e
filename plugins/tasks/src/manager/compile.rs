//! Compile-time helpers of the `task` section: the scene's cameras, checks of events and
//! ranges, `extends` files, and configuring a term from the registry.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use modesuite_engine::registry::SectionCompileContext;
use modesuite_engine::scene::SceneError;

use crate::desc::{EventDesc, TaskDesc};
use crate::events::{EngineEvent, TaskEvent, TaskEventEntry};
use crate::terms::{configure_any, Configure, TaskTerm};
use modesuite_engine::events::EventEntry;

/// The cameras of the scene: its render section's and those other sections bring (a robot
/// file's), the render section's first: name -> (width, height).
pub(super) fn scene_cameras(
    ctx: &SectionCompileContext,
) -> Result<BTreeMap<String, (u32, u32)>, SceneError> {
    // The render section reports its own errors with their place; an unreadable one leaves
    // no cameras of its own here.
    let mut cfg: modesuite_render::RenderConfig = ctx
        .extension(modesuite_render::config::EXTENSION_KEY)
        .and_then(|text| modesuite_engine::scene::ron_options().from_str(text).ok())
        .unwrap_or_default();
    cfg.add_mounted(ctx.mounted_cameras.iter().cloned());
    Ok(cfg
        .cameras
        .iter()
        .map(|c| (c.name.clone(), (c.width, c.height)))
        .collect())
}

/// Checks that an event's `object` is in the scene; a robot link (`robot/link`, spawned by the
/// robots section after the task compiles) is checked when the event runs.
fn check_object(epath: &str, object: &str, cfg: &Configure) -> Result<(), SceneError> {
    if object.contains('/') {
        return Ok(());
    }
    cfg.object(object)
        .map_err(|m| serr(&format!("{epath}.object"), object, m))
}

/// Checks a `(lo, hi)` range: finite, `lo <= hi`, `lo >= 0` (`lo > 0` when `positive`).
fn check_range(
    path: &str,
    (lo, hi): (f64, f64),
    positive: bool,
    (low, high): (&str, &str),
    unit: &str,
) -> Result<(), SceneError> {
    let low_ok = if positive { lo > 0.0 } else { lo >= 0.0 };
    if lo.is_finite() && hi.is_finite() && low_ok && lo <= hi {
        return Ok(());
    }
    let op = if positive { "<" } else { "<=" };
    Err(serr(
        path,
        format!("({lo}, {hi})"),
        format!("finite ({low}, {high}) with 0 {op} {low} <= {high}{unit}"),
    ))
}

/// Checks an event of the task section (`wrapper`: the `Startup`/`Interval` it is inside).
/// Checks one entry of a task's `events` (a built-in event's values, a registered event's
/// configuration, the wrappers' rules) and returns the configured registered event, if the
/// entry is one.
pub(super) fn check_event(
    ctx: &SectionCompileContext,
    epath: &str,
    e: &EventDesc,
    cfg: &Configure,
    wrapper: Option<&str>,
) -> Result<Option<Arc<dyn TaskEvent>>, SceneError> {
    match e {
        EventDesc::Event { event, params } => {
            let is_event = |t: &modesuite_engine::registry::TermEntry| {
                t.payload.is::<TaskEventEntry>() || t.payload.is::<EventEntry>()
            };
            let entry = ctx
                .registry
                .terms
                .get(event)
                .filter(|t| is_event(t))
                .ok_or_else(|| {
                    serr(
                        &format!("{epath}.event"),
                        format!("\"{event}\""),
                        format!(
                            "a registered event: [{}]",
                            ctx.registry
                                .terms
                                .iter()
                                .filter(|(_, t)| is_event(t))
                                .map(|(n, _)| n.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    )
                })?;
            let ron = params.as_ref().map_or("()", |p| p.get_ron());
            let configured = match entry.payload.downcast_ref::<TaskEventEntry>() {
                Some(task_event) => task_event.0.configure(ron, cfg),
                // an engine event (a compiled plugin's, or a static plugin's through
                // `TermEntry::event`)
                None => entry
                    .payload
                    .downcast_ref::<EventEntry>()
                    .ok_or_else(|| "not an event".to_string())
                    .and_then(|e| e.0.configure(ron))
                    .map(|e| Arc::new(EngineEvent(e)) as Arc<dyn TaskEvent>),
            }
            .map_err(|m| serr(&format!("{epath}.params"), ron.trim(), m))?;
            if wrapper == Some("Interval") && !configured.interval_safe() {
                return Err(serr(
                    &format!("{epath}.event"),
                    format!("\"{event}\""),
                    "an event that moves no body (this one is for resets and Startup only)",
                ));
            }
            return Ok(Some(configured));
        }
        EventDesc::RobotPose { xy, yaw, carry } => {
            if !(xy.is_finite() && *xy >= 0.0 && yaw.is_finite() && *yaw >= 0.0) {
                return Err(serr(epath, format!("{e:?}"), "finite xy >= 0 and yaw >= 0"));
            }
            for c in carry {
                cfg.object(c)
                    .map_err(|m| serr(&format!("{epath}.carry"), c.clone(), m))?;
            }
        }
        EventDesc::Friction { object, range } => {
            check_object(epath, object, cfg)?;
            check_range(
                &format!("{epath}.range"),
                *range,
                false,
                ("lowest", "highest"),
                "",
            )?;
        }
        EventDesc::ObjectOffset { object, xy } => {
            check_object(epath, object, cfg)?;
            if !(xy.is_finite() && *xy >= 0.0) {
                return Err(serr(
                    &format!("{epath}.xy"),
                    xy.to_string(),
                    "a finite xy >= 0",
                ));
            }
        }
        EventDesc::Material {
            object,
            youngs_modulus: (lo, hi),
        } => {
            check_object(epath, object, cfg)?;
            check_range(
                &format!("{epath}.youngs_modulus"),
                (*lo, *hi),
                true,
                ("lowest", "highest"),
                ", Pa",
            )?;
        }
        EventDesc::Push { object, velocity } => {
            check_object(epath, object, cfg)?;
            let (x, y, z) = *velocity;
            if ![x, y, z].iter().all(|v| v.is_finite() && *v >= 0.0) {
                return Err(serr(
                    &format!("{epath}.velocity"),
                    format!("{velocity:?}"),
                    "finite half-widths >= 0, m/s",
                ));
            }
        }
        EventDesc::Startup(inner) | EventDesc::Interval { event: inner, .. } => {
            let kind = if matches!(e, EventDesc::Startup(_)) {
                "Startup"
            } else {
                "Interval"
            };
            if let Some(outer) = wrapper {
                return Err(serr(
                    epath,
                    kind,
                    format!("an event inside {outer}(...) (Startup and Interval do not nest)"),
                ));
            }
            if let EventDesc::Interval {
                every: (lo, hi), ..
            } = e
            {
                check_range(
                    &format!("{epath}.every"),
                    (*lo, *hi),
                    true,
                    ("shortest", "longest"),
                    ", s",
                )?;
                if matches!(
                    **inner,
                    EventDesc::RobotPose { .. } | EventDesc::ObjectOffset { .. }
                ) {
                    return Err(serr(
                        &format!("{epath}.event"),
                        format!("{inner:?}"),
                        "Friction, Material or Push (RobotPose and ObjectOffset teleport objects: reset or Startup only)",
                    ));
                }
            }
            let ipath = if kind == "Startup" {
                format!("{epath}.0")
            } else {
                format!("{epath}.event")
            };
            return check_event(ctx, &ipath, inner, cfg, Some(kind));
        }
    }
    Ok(None)
}

pub(super) fn serr(path: &str, value: impl Into<String>, msg: impl Into<String>) -> SceneError {
    SceneError::semantic(path.to_string(), value.into(), msg.into())
}

/// Reads `file` (a `*.task.ron` holding one task section) and the files it extends.
fn load_extends(
    base_dir: &Path,
    file: &str,
    depth: usize,
    path: &str,
) -> Result<TaskDesc, SceneError> {
    if depth > 8 {
        return Err(serr(path, file, "at most 8 levels of `extends`"));
    }
    // a scene names task files beside it or in its subfolders, never elsewhere on the machine
    let inside = Path::new(file)
        .components()
        .all(|c| matches!(c, std::path::Component::Normal(_)));
    if !inside || !file.ends_with(".task.ron") {
        return Err(serr(
            path,
            file,
            "a `*.task.ron` file in the scene's folder or below it (a relative path without `..`)",
        ));
    }
    let full = base_dir.join(file);
    let text = match full
        .to_str()
        .and_then(|f| f.strip_prefix(crate::EMBEDDED_DIR))
        .map(|f| f.trim_start_matches('/'))
    {
        Some(rel) => crate::embedded(rel)
            .ok_or_else(|| serr(path, file, format!("no embedded file {rel}")))?
            .to_string(),
        None => std::fs::read_to_string(&full)
            .map_err(|e| serr(path, file, format!("cannot read {}: {e}", full.display())))?,
    };
    let desc: TaskDesc = crate::ron_options()
        .from_str(&text)
        .map_err(|e| serr(path, file, format!("{}:{}", full.display(), e)))?;
    resolve_extends(desc, full.parent().unwrap_or(base_dir), depth + 1, path)
}

pub(super) fn resolve_extends(
    desc: TaskDesc,
    base_dir: &Path,
    depth: usize,
    path: &str,
) -> Result<TaskDesc, SceneError> {
    match desc.extends.clone() {
        None => Ok(desc),
        Some(f) => {
            let parent = load_extends(base_dir, &f, depth, &format!("{path}.extends"))?;
            Ok(desc.over(parent))
        }
    }
}

pub(super) fn configure(
    ctx: &SectionCompileContext,
    cfg: &mut Configure,
    path: String,
    name: &str,
    params: Option<&ron::value::RawValue>,
) -> Result<Arc<dyn TaskTerm>, SceneError> {
    let entry = ctx.registry.terms.get(name).ok_or_else(|| {
        serr(
            &path,
            format!("term: \"{name}\""),
            format!(
                "a registered task term: [{}]",
                ctx.registry
                    .terms
                    .keys()
                    .map(String::as_str)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )
    })?;
    let ron = params.map_or("()", |p| p.get_ron());
    configure_any(entry.payload.as_ref(), ron, cfg)
        .ok_or_else(|| {
            serr(
                &path,
                format!("term: \"{name}\""),
                "a term a task can evaluate (a task term or an engine term)",
            )
        })?
        .map_err(|e| serr(&format!("{path}.params"), ron.trim(), e))
}
