//! Env state: snapshots (reset = restore) and a bit-exact hash (determinism checks).
//!
//! Every solver context implements [`Stateful`] and is registered with
//! [`SimApp::register_stateful`](crate::SimApp::register_stateful); components that carry state
//! (poses, velocities) are registered with `register_stateful_component`. A [`Snapshot`] holds a
//! copy of all of them; restoring it makes the next step bit-identical to the step that followed
//! the snapshot originally. The same parts are written to disk through [`Persist`]
//! ([`crate::checkpoint`]).

use std::any::Any;

use bevy_ecs::component::Mutable;
use bevy_ecs::prelude::*;

use crate::codec::{Decoder, Encoder, Persist, StateError};

/// A resource that is part of the env state: copied in memory for resets ([`Snapshot`]) and
/// written to state files through its [`Persist`] codec.
pub trait Stateful: Persist {
    /// A complete copy of the state (solver caches that change results included).
    fn save_state(&self) -> Box<dyn Any + Send + Sync>;
    /// Restores a copy made by `save_state` of the same type; a copy of another type is an
    /// error (see [`mismatch`]).
    fn load_state(&mut self, state: &(dyn Any + Send + Sync)) -> Result<(), StateError>;
    /// Feeds every bit of the state that affects future steps into the hasher.
    fn hash_state(&self, h: &mut StateHasher);
}

/// A component value that can be hashed bit-exactly.
pub trait HashState {
    /// Feeds the value's bits into the hasher.
    fn hash_state(&self, h: &mut StateHasher);
}

/// 64-bit FNV-1a over the exact bit patterns written (floats by `to_bits`).
#[derive(Debug, Clone, Copy)]
pub struct StateHasher(u64);

impl Default for StateHasher {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl StateHasher {
    /// Hashes raw bytes.
    pub fn write_bytes(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 ^= u64::from(*b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01B3);
        }
    }
    /// Hashes a u64.
    pub fn write_u64(&mut self, x: u64) {
        self.write_bytes(&x.to_le_bytes());
    }
    /// Hashes the bits of an f64.
    pub fn write_f64(&mut self, x: f64) {
        self.write_u64(x.to_bits());
    }
    /// Hashes the bits of an f32.
    pub fn write_f32(&mut self, x: f32) {
        self.write_bytes(&x.to_bits().to_le_bytes());
    }
    /// Hashes a string.
    pub fn write_str(&mut self, s: &str) {
        self.write_u64(s.len() as u64);
        self.write_bytes(s.as_bytes());
    }
    /// The hash value.
    pub fn finish(&self) -> u64 {
        self.0
    }
}

/// The error of a [`Stateful::load_state`] handed a copy of another type.
pub fn mismatch<T>() -> StateError {
    StateError::part(
        std::any::type_name::<T>(),
        "the saved copy is of another type (a snapshot of another app)",
    )
}

/// [`Stateful::load_state`] of a part whose saved copy is its whole value (`save_state` returns
/// `Box::new(self.clone())`): copies it back, or a [`mismatch`] for a copy of another type.
pub fn restore_clone<T: Clone + 'static>(
    this: &mut T,
    state: &(dyn Any + Send + Sync),
) -> Result<(), StateError> {
    this.clone_from(state.downcast_ref::<T>().ok_or_else(mismatch::<T>)?);
    Ok(())
}

type SaveFn = fn(&World) -> Box<dyn Any + Send + Sync>;
type LoadFn = fn(&mut World, &(dyn Any + Send + Sync)) -> Result<(), StateError>;
type HashFn = fn(&World, &mut StateHasher);
type EncodeFn = fn(&World, &mut Encoder);
type DecodeFn = fn(&mut World, &mut Decoder<'_>) -> Result<(), StateError>;

struct StateEntry {
    name: &'static str,
    save: SaveFn,
    load: LoadFn,
    hash: HashFn,
    encode: EncodeFn,
    decode: DecodeFn,
}

/// The list of state parts of an app (resource).
#[derive(Resource, Default)]
pub struct StateRegistry {
    entries: Vec<StateEntry>,
}

fn save_resource<R: Resource + Component<Mutability = Mutable> + Stateful>(
    world: &World,
) -> Box<dyn Any + Send + Sync> {
    match world.get_resource::<R>() {
        Some(r) => r.save_state(),
        None => Box::new(()),
    }
}

fn load_resource<R: Resource + Component<Mutability = Mutable> + Stateful>(
    world: &mut World,
    s: &(dyn Any + Send + Sync),
) -> Result<(), StateError> {
    match world.get_resource_mut::<R>() {
        Some(mut r) => r.load_state(s),
        None if s.is::<()>() => Ok(()),
        None => Err(StateError::part(
            std::any::type_name::<R>(),
            "saved, but this app has no such resource",
        )),
    }
}

fn encode_resource<R: Resource + Component<Mutability = Mutable> + Stateful>(
    world: &World,
    e: &mut Encoder,
) {
    let r = world.get_resource::<R>();
    e.put(&r.is_some());
    if let Some(r) = r {
        r.encode(e);
    }
}

fn decode_resource<R: Resource + Component<Mutability = Mutable> + Stateful>(
    world: &mut World,
    d: &mut Decoder<'_>,
) -> Result<(), StateError> {
    let present: bool = d.take()?;
    match (present, world.get_resource_mut::<R>()) {
        (true, Some(mut r)) => r.decode(d),
        (false, None) => Ok(()),
        (true, None) => Err(StateError::part(d.part(), "in the file, not in this env")),
        (false, Some(_)) => Err(StateError::part(d.part(), "in this env, not in the file")),
    }
}

fn hash_resource<R: Resource + Component<Mutability = Mutable> + Stateful>(
    world: &World,
    h: &mut StateHasher,
) {
    if let Some(r) = world.get_resource::<R>() {
        r.hash_state(h);
    }
}

fn save_component<C: Component + Clone>(world: &World) -> Box<dyn Any + Send + Sync> {
    let mut out: Vec<(Entity, C)> = Vec::new();
    if let Some(mut q) = world.try_query::<(Entity, &C)>() {
        out.extend(q.iter(world).map(|(e, c)| (e, c.clone())));
    }
    out.sort_by_key(|(e, _)| *e);
    Box::new(out)
}

fn load_component<C: Component<Mutability = Mutable> + Clone>(
    world: &mut World,
    s: &(dyn Any + Send + Sync),
) -> Result<(), StateError> {
    let list = s
        .downcast_ref::<Vec<(Entity, C)>>()
        .ok_or_else(mismatch::<C>)?;
    for (e, c) in list {
        match world.get_mut::<C>(*e) {
            Some(mut slot) => *slot = c.clone(),
            None => {
                return Err(StateError::part(
                    std::any::type_name::<C>(),
                    format!("entity {e} of the copy has no such component here"),
                ))
            }
        }
    }
    Ok(())
}

fn sorted_components<C: Component>(world: &World) -> Vec<(Entity, &C)> {
    let mut items: Vec<(Entity, &C)> = Vec::new();
    if let Some(mut q) = world.try_query::<(Entity, &C)>() {
        items.extend(q.iter(world));
    }
    items.sort_by_key(|(e, _)| *e);
    items
}

fn encode_component<C: Component + Persist>(world: &World, e: &mut Encoder) {
    let items = sorted_components::<C>(world);
    e.put(&(items.len() as u64));
    for (entity, c) in items {
        e.put(&entity.to_bits());
        c.encode(e);
    }
}

fn decode_component<C: Component<Mutability = Mutable> + Persist>(
    world: &mut World,
    d: &mut Decoder<'_>,
) -> Result<(), StateError> {
    let here: Vec<Entity> = sorted_components::<C>(world)
        .into_iter()
        .map(|(e, _)| e)
        .collect();
    d.take_len("entities", here.len())?;
    for entity in here {
        let bits: u64 = d.take()?;
        if bits != entity.to_bits() {
            return Err(StateError::part(
                d.part(),
                format!("the file's entity {bits:#x} is {entity} here"),
            ));
        }
        let mut c = world
            .get_mut::<C>(entity)
            .expect("the entity was just queried with this component");
        c.decode(d)?;
    }
    Ok(())
}

fn hash_component<C: Component + HashState>(world: &World, h: &mut StateHasher) {
    for (e, c) in sorted_components::<C>(world) {
        h.write_u64(e.to_bits());
        c.hash_state(h);
    }
}

impl StateRegistry {
    /// Adds a stateful resource (idempotent).
    pub fn add_resource<R: Resource + Component<Mutability = Mutable> + Stateful>(&mut self) {
        let name = std::any::type_name::<R>();
        if self.entries.iter().any(|e| e.name == name) {
            return;
        }
        self.entries.push(StateEntry {
            name,
            save: save_resource::<R>,
            load: load_resource::<R>,
            hash: hash_resource::<R>,
            encode: encode_resource::<R>,
            decode: decode_resource::<R>,
        });
    }

    /// Adds a stateful component type (idempotent).
    pub fn add_component<C: Component<Mutability = Mutable> + Clone + HashState + Persist>(
        &mut self,
    ) {
        let name = std::any::type_name::<C>();
        if self.entries.iter().any(|e| e.name == name) {
            return;
        }
        self.entries.push(StateEntry {
            name,
            save: save_component::<C>,
            load: load_component::<C>,
            hash: hash_component::<C>,
            encode: encode_component::<C>,
            decode: decode_component::<C>,
        });
    }

    /// Type names of the registered state parts, in registration order.
    pub fn names(&self) -> Vec<&'static str> {
        self.entries.iter().map(|e| e.name).collect()
    }
}

/// A full copy of an env's state.
pub struct Snapshot {
    parts: Vec<(&'static str, Box<dyn Any + Send + Sync>)>,
}

impl Snapshot {
    /// Copies every registered state part of `world`.
    pub fn take(world: &World) -> Self {
        let reg = world.resource::<StateRegistry>();
        Self {
            parts: reg
                .entries
                .iter()
                .map(|e| (e.name, (e.save)(world)))
                .collect(),
        }
    }

    /// Writes the copy back into `world` (the same app it was taken from). A copy of another
    /// app (other state parts, or parts of other types) is an error; the parts before the one
    /// that failed are then already restored.
    pub fn restore(&self, world: &mut World) -> Result<(), StateError> {
        let loads: Vec<(&'static str, LoadFn)> = world
            .resource::<StateRegistry>()
            .entries
            .iter()
            .map(|e| (e.name, e.load))
            .collect();
        let names: Vec<&str> = self.parts.iter().map(|(n, _)| *n).collect();
        if names.len() != loads.len() || names.iter().zip(&loads).any(|(a, (b, _))| a != b) {
            return Err(StateError::Foreign(format!(
                "the snapshot has the state parts {names:?}, this app {:?}",
                loads.iter().map(|(n, _)| *n).collect::<Vec<_>>()
            )));
        }
        for ((_, part), (_, load)) in self.parts.iter().zip(&loads) {
            load(world, part.as_ref())?;
        }
        Ok(())
    }
}

/// Every registered state part of `world`, encoded, by name (what a state file stores).
pub fn encode_parts(world: &World) -> Result<Vec<(String, Vec<u8>)>, StateError> {
    world
        .resource::<StateRegistry>()
        .entries
        .iter()
        .map(|entry| {
            let mut e = Encoder::default();
            (entry.encode)(world, &mut e);
            let bytes = e
                .into_bytes()
                .map_err(|m| StateError::part(entry.name, m))?;
            Ok((entry.name.to_string(), bytes))
        })
        .collect()
}

/// Decodes parts written by [`encode_parts`] into `world`, whose registered parts must have the
/// same names in the same order. Stops at the first failure (the caller restores a backup).
pub fn decode_parts(world: &mut World, parts: &[(String, Vec<u8>)]) -> Result<(), StateError> {
    let entries: Vec<(&'static str, DecodeFn)> = world
        .resource::<StateRegistry>()
        .entries
        .iter()
        .map(|e| (e.name, e.decode))
        .collect();
    if parts.len() != entries.len() {
        return Err(StateError::Foreign(format!(
            "{} state parts in the file, {} in this env",
            parts.len(),
            entries.len()
        )));
    }
    for ((name, bytes), (mine, decode)) in parts.iter().zip(entries) {
        if name != mine {
            return Err(StateError::Foreign(format!(
                "state part {name} in the file where this env has {mine}"
            )));
        }
        let mut d = Decoder::new(bytes, mine);
        decode(world, &mut d)?;
        d.finish()?;
    }
    Ok(())
}

/// Bit-exact hash of every registered state part of `world`.
pub fn state_hash(world: &World) -> u64 {
    let mut h = StateHasher::default();
    for e in &world.resource::<StateRegistry>().entries {
        h.write_str(e.name);
        (e.hash)(world, &mut h);
    }
    h.finish()
}

/// State slots of plugins that cannot own a Rust resource (compiled C ABI plugins): `len` f64
/// values per owner, zero at spawn, saved in snapshots and hashed like every other part of the
/// state. Declared with [`SimApp::declare_plugin_state`](crate::SimApp::declare_plugin_state).
#[derive(Resource, Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PluginStates {
    slots: std::collections::BTreeMap<String, Vec<f64>>,
}

impl PluginStates {
    /// Declares `len` slots for `owner` (zeroed; an existing declaration is resized).
    pub fn declare(&mut self, owner: &str, len: usize) {
        self.slots
            .entry(owner.to_string())
            .or_default()
            .resize(len, 0.0);
    }

    /// The slots of `owner` (empty when none were declared).
    pub fn get(&self, owner: &str) -> &[f64] {
        self.slots.get(owner).map_or(&[], Vec::as_slice)
    }

    /// The slots of `owner`, mutable (empty when none were declared).
    pub fn get_mut(&mut self, owner: &str) -> &mut [f64] {
        self.slots.get_mut(owner).map_or(&mut [], Vec::as_mut_slice)
    }
}

crate::persist_by_serde!(PluginStates);

impl Stateful for PluginStates {
    fn save_state(&self) -> Box<dyn Any + Send + Sync> {
        Box::new(self.clone())
    }
    fn load_state(&mut self, state: &(dyn Any + Send + Sync)) -> Result<(), StateError> {
        restore_clone(self, state)
    }
    fn hash_state(&self, h: &mut StateHasher) {
        for (owner, slots) in &self.slots {
            h.write_str(owner);
            for x in slots {
                h.write_f64(*x);
            }
        }
    }
}
