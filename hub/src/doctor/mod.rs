//! `robot-agent doctor`: checks a machine before or while the agent runs (models and their checksums, ports, the
//! data directory, the HTTPS certificate, satellites) and prints one line per finding with its fix. Each check
//! gathers facts, then a pure function turns them into findings, so that the findings are unit-tested.

mod agent;
mod certificate;
mod disk;
mod finding;
mod models;
mod ports;

use std::path::PathBuf;

use crate::config::Config;

pub use finding::{Finding, Level};
pub use models::default_models_dir;

/// What the doctor is told beyond the configuration.
#[derive(Debug, Clone)]
pub struct Options {
    /// The models folder (`models/` of the checkout, or the installed one).
    pub models: PathBuf,
}

/// Runs every check against the configuration and returns the findings, in the order of the checks.
pub fn examine(config: &Config, options: &Options) -> Vec<Finding> {
    let mut findings = models::check(config, &options.models);
    let ports = ports::probe(config);
    findings.extend(ports::findings(&ports));
    findings.extend(disk::check(&config.server.data_dir));
    findings.extend(certificate::check(config));
    findings.extend(agent::check(config, &ports));
    findings
}

/// The exit status for scripts: 0 when nothing is a problem (warnings included), 1 otherwise.
pub fn exit_code(findings: &[Finding]) -> i32 {
    i32::from(findings.iter().any(|f| f.level == Level::Problem))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_problem_makes_the_exit_code_one_and_warnings_do_not() {
        let warn = Finding::warning("data", "low", "free space");
        assert_eq!(exit_code(&[Finding::ok("models", "fine"), warn.clone()]), 0);
        assert_eq!(
            exit_code(&[warn, Finding::problem("ports", "busy", "stop it")]),
            1
        );
        assert_eq!(exit_code(&[]), 0);
    }
}
