//! The built-in modules and the switch that picks them from the configuration.

use crate::config::Config;
use crate::module::Module;

/// The enabled built-in modules, in start order.
pub fn builtin(config: &Config) -> Vec<Box<dyn Module>> {
    let all: Vec<Box<dyn Module>> = vec![];
    all.into_iter()
        .filter(|m| config.module_enabled(m.name()))
        .collect()
}
