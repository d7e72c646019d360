//! The model slot: the model in force, the one it replaced (for revert), the version counter and
//! the learned model of every geometry seen (a layout seen before gets its model back without
//! pulses). Every model goes in through `swap`, which checks it first.

use std::collections::HashMap;

use crate::model::{Model, ModelSource, SwapRejection};

#[derive(Clone, Default, serde::Serialize, serde::Deserialize)]
pub(super) struct ModelSlot {
    current: Option<Model>,
    previous: Option<Model>,
    versions: u64,
    cache: HashMap<u64, Model>,
}

impl ModelSlot {
    /// The model in force.
    pub(super) fn current(&self) -> Option<&Model> {
        self.current.as_ref()
    }

    /// Validate `model` for `n` thrusters and install it, numbered and marked with `source`;
    /// the one it replaces becomes the previous. Returns what was installed.
    pub(super) fn swap(
        &mut self,
        mut model: Model,
        source: ModelSource,
        n: usize,
        max_rel_err: f64,
    ) -> Result<Model, SwapRejection> {
        model.check(n, max_rel_err)?;
        // A loaded model keeps the version it was saved with when the counter is below it
        // (issue 27: a saved v8 came back as v1); otherwise it gets the next number, so the
        // daemon's versions never go back.
        self.versions = if source == ModelSource::Loaded {
            (self.versions + 1).max(model.version)
        } else {
            self.versions + 1
        };
        model.version = self.versions;
        model.source = source;
        if let Some(old) = self.current.replace(model.clone()) {
            self.previous = Some(old);
        }
        Ok(model)
    }

    /// The model in force changed in place by `f` (what it claims, not what it is: a bound
    /// restated) under the next version number; the previous model stays the one a revert
    /// goes back to. Returns what is now in force, None without a model.
    pub(super) fn restate_current(&mut self, f: impl FnOnce(&mut Model)) -> Option<Model> {
        let current = self.current.as_mut()?;
        f(current);
        self.versions += 1;
        current.version = self.versions;
        Some(current.clone())
    }

    /// The model the current one replaced, taken out of the slot (revert).
    pub(super) fn take_previous(&mut self) -> Option<Model> {
        self.previous.take()
    }

    /// No model in force any more; the dropped one becomes the previous.
    pub(super) fn drop_current(&mut self) {
        if let Some(old) = self.current.take() {
            self.previous = Some(old);
        }
    }

    /// The learned model of the geometry with this key, if it was seen before.
    pub(super) fn cached(&self, key: u64) -> Option<Model> {
        self.cache.get(&key).cloned()
    }

    /// Remember the model in force as the learned model of the geometry with this key.
    pub(super) fn remember_current(&mut self, key: u64) {
        if let Some(m) = self.current.clone() {
            self.cache.insert(key, m);
        }
    }
}
