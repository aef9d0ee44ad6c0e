//! Env state: snapshots (reset = restore) and a bit-exact hash (determinism checks).
//!
//! Every solver context implements [`Stateful`] and is registered with
//! [`SimApp::register_stateful`](crate::SimApp::register_stateful); components that carry state
//! (poses, velocities) are registered with `register_stateful_component`. A [`Snapshot`] holds a
//! copy of all of them; restoring it makes the next step bit-identical to the step that followed
//! the snapshot originally.

use std::any::Any;

use bevy_ecs::component::Mutable;
use bevy_ecs::prelude::*;

/// A resource that is part of the env state.
pub trait Stateful {
    /// A complete copy of the state (solver caches that change results included).
    fn save_state(&self) -> Box<dyn Any + Send + Sync>;
    /// Restores a copy made by `save_state` of the same type (other types are ignored).
    fn load_state(&mut self, state: &(dyn Any + Send + Sync));
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

type SaveFn = fn(&World) -> Box<dyn Any + Send + Sync>;
type LoadFn = fn(&mut World, &(dyn Any + Send + Sync));
type HashFn = fn(&World, &mut StateHasher);

struct StateEntry {
    name: &'static str,
    save: SaveFn,
    load: LoadFn,
    hash: HashFn,
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
) {
    if let Some(mut r) = world.get_resource_mut::<R>() {
        r.load_state(s);
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
) {
    if let Some(list) = s.downcast_ref::<Vec<(Entity, C)>>() {
        for (e, c) in list {
            if let Some(mut slot) = world.get_mut::<C>(*e) {
                *slot = c.clone();
            }
        }
    }
}

fn hash_component<C: Component + HashState>(world: &World, h: &mut StateHasher) {
    let mut items: Vec<(Entity, &C)> = Vec::new();
    if let Some(mut q) = world.try_query::<(Entity, &C)>() {
        items.extend(q.iter(world));
    }
    items.sort_by_key(|(e, _)| *e);
    for (e, c) in items {
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
        });
    }

    /// Adds a stateful component type (idempotent).
    pub fn add_component<C: Component<Mutability = Mutable> + Clone + HashState>(&mut self) {
        let name = std::any::type_name::<C>();
        if self.entries.iter().any(|e| e.name == name) {
            return;
        }
        self.entries.push(StateEntry {
            name,
            save: save_component::<C>,
            load: load_component::<C>,
            hash: hash_component::<C>,
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

    /// Writes the copy back into `world` (the same app it was taken from).
    pub fn restore(&self, world: &mut World) {
        let loads: Vec<(&'static str, LoadFn)> = world
            .resource::<StateRegistry>()
            .entries
            .iter()
            .map(|e| (e.name, e.load))
            .collect();
        for (name, part) in &self.parts {
            if let Some((_, load)) = loads.iter().find(|(n, _)| n == name) {
                load(world, part.as_ref());
            }
        }
    }
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
#[derive(Resource, Debug, Clone, Default, PartialEq)]
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

impl Stateful for PluginStates {
    fn save_state(&self) -> Box<dyn Any + Send + Sync> {
        Box::new(self.clone())
    }
    fn load_state(&mut self, state: &(dyn Any + Send + Sync)) {
        if let Some(s) = state.downcast_ref::<Self>() {
            self.clone_from(s);
        }
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
