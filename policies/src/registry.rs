//! Policies by name: the built-in `pd` baseline, the shipped RL model `rl`, and any loaded model.

use crate::{LoadError, OnnxPolicy, PdPolicy, Policy};
use std::collections::BTreeMap;

/// A policy name that is not loaded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("unknown policy `{name}` (available: {available})")]
pub struct UnknownPolicy {
    /// The requested name.
    pub name: String,
    /// Comma-separated names that exist.
    pub available: String,
}

/// The loaded policies, each evaluated once per tick on all UAVs that use it.
pub struct PolicyRegistry {
    policies: BTreeMap<String, Box<dyn Policy>>,
}

impl PolicyRegistry {
    /// A registry holding the PD baseline as `pd` with saturation δ.
    pub fn with_pd(delta: f64) -> Self {
        let mut policies: BTreeMap<String, Box<dyn Policy>> = BTreeMap::new();
        policies.insert("pd".into(), Box::new(PdPolicy { delta, ..PdPolicy::default() }));
        Self { policies }
    }

    /// The standard set: `pd` and the shipped RL model as `rl` (embedded in the binary).
    pub fn standard(delta: f64) -> Result<Self, LoadError> {
        let mut registry = Self::with_pd(delta);
        registry.insert(crate::SHIPPED_MODEL, Box::new(crate::shipped_model()?));
        Ok(registry)
    }

    /// Adds the ONNX model at `path` under `name` (checked against the contract first).
    pub fn load(&mut self, name: &str, path: &std::path::Path) -> Result<(), LoadError> {
        let policy = OnnxPolicy::load(name, path)?;
        self.insert(name, Box::new(policy));
        Ok(())
    }

    /// Adds (or replaces) a policy under `name`.
    pub fn insert(&mut self, name: impl Into<String>, policy: Box<dyn Policy>) {
        self.policies.insert(name.into(), policy);
    }

    /// Checks that `name` is loaded.
    pub fn check(&self, name: &str) -> Result<(), UnknownPolicy> {
        if self.policies.contains_key(name) {
            Ok(())
        } else {
            Err(UnknownPolicy { name: name.into(), available: self.names().collect::<Vec<_>>().join(", ") })
        }
    }

    /// Names of the loaded policies.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.policies.keys().map(String::as_str)
    }

    /// Every policy with its name, for evaluating each once per tick.
    pub fn iter_mut(&mut self) -> impl Iterator<Item = (&str, &mut (dyn Policy + 'static))> {
        self.policies.iter_mut().map(|(name, p)| (name.as_str(), p.as_mut()))
    }

    /// The policy called `name`.
    pub fn get_mut(&mut self, name: &str) -> Option<&mut (dyn Policy + 'static)> {
        self.policies.get_mut(name).map(|p| p.as_mut())
    }
}
