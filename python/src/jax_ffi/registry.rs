//! The process-wide table of functions the FFI handler serves: one XLA target for every model,
//! the function chosen by an integer handle passed as a call attribute.
//!
//! Entries live as long as the process. JAX keeps compiled executables (with the handle baked
//! in) in caches whose lifetime Python code does not see, so freeing an entry when its Python
//! object dies could make a cached executable fail later. Identical configurations (same model
//! text, inputs, columns, event slots, fixed values and options) share one entry, so rebuilding a
//! function in a loop does not grow the table.

use std::collections::HashMap;
use std::sync::{Arc, LazyLock, RwLock};

use super::function::Function;

#[derive(Default)]
struct Table {
    by_handle: HashMap<u64, Arc<Function>>,
    by_key: HashMap<String, u64>,
}

static TABLE: LazyLock<RwLock<Table>> = LazyLock::new(Default::default);

fn read() -> std::sync::RwLockReadGuard<'static, Table> {
    // Writers only insert whole entries, so a poisoned lock still guards a consistent table.
    TABLE.read().unwrap_or_else(|p| p.into_inner())
}

/// The handle of the function registered under `key`, if any.
pub fn find(key: &str) -> Option<u64> {
    read().by_key.get(key).copied()
}

/// Registers `function` under `key` and returns its handle (the existing one when another thread
/// registered the same key first). Handles start at 1.
pub fn insert(key: String, function: Function) -> u64 {
    let mut table = TABLE.write().unwrap_or_else(|p| p.into_inner());
    if let Some(&h) = table.by_key.get(&key) {
        return h;
    }
    let handle = table.by_handle.len() as u64 + 1;
    table.by_handle.insert(handle, Arc::new(function));
    table.by_key.insert(key, handle);
    handle
}

/// The function behind `handle`.
pub fn get(handle: u64) -> Option<Arc<Function>> {
    read().by_handle.get(&handle).cloned()
}
