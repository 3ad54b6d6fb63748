//! The `doctor` subcommand of the hub's binaries: checks a machine before or while the hub runs (ports, the data
//! directory, the HTTPS certificate, the page's secure context, the clock against the hub's, satellites) and prints
//! one line per finding with its fix. Each check gathers facts, then a pure function turns them into findings, so
//! that the findings are unit-tested. A binary adds checks of its own parts ([`Check`]: robot-agent's models), since
//! the hub knows no agent part.

mod agent;
mod certificate;
mod clock;
mod disk;
mod finding;
mod ports;
mod secure;

use crate::config::Config;

pub use finding::{Finding, Level};

/// What the doctor is told beyond the configuration.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// `--from`: the address or host name a browser will open the page by (`robot.local`, `192.168.1.20`).
    pub from: Option<String>,
    /// The `doctor` subcommand's arguments, where a binary's [`Check`]s read the options they added.
    pub args: clap::ArgMatches,
}

/// A check that a binary adds to the hub's, for parts the hub does not know (robot-agent's models).
pub trait Check: std::fmt::Debug + Sync {
    /// The `doctor` subcommand with this check's options added (none by default).
    fn arguments(&self, doctor: clap::Command) -> clap::Command {
        doctor
    }

    /// The findings for `config`, with the subcommand's arguments `args`.
    fn examine(&self, config: &Config, args: &clap::ArgMatches) -> Vec<Finding>;
}

/// Runs the binary's checks `extra` and then the hub's against the configuration, and returns the findings in the
/// order of the checks.
pub fn examine(config: &Config, options: &Options, extra: &[&dyn Check]) -> Vec<Finding> {
    let mut findings: Vec<Finding> = extra
        .iter()
        .flat_map(|c| c.examine(config, &options.args))
        .collect();
    let ports = ports::probe(config);
    findings.extend(ports::findings(&ports));
    findings.extend(disk::check(&config.server.data_dir));
    findings.extend(certificate::check(config));
    findings.extend(secure::check(config, options.from.as_deref()));
    findings.extend(clock::check(config));
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

    /// A binary's check, with an option of its own.
    #[derive(Debug)]
    struct Counted;

    impl Check for Counted {
        fn arguments(&self, doctor: clap::Command) -> clap::Command {
            doctor.arg(clap::Arg::new("widgets").long("widgets"))
        }

        fn examine(&self, _config: &Config, args: &clap::ArgMatches) -> Vec<Finding> {
            let widgets = args
                .get_one::<String>("widgets")
                .cloned()
                .unwrap_or_default();
            vec![Finding::ok("widgets", format!("{widgets} widgets"))]
        }
    }

    #[test]
    fn a_binarys_checks_come_first_with_the_options_they_added() {
        let doctor = Counted.arguments(clap::Command::new("doctor"));
        let args = doctor
            .try_get_matches_from(["doctor", "--widgets", "3"])
            .expect("the check's option parses");
        let mut config = Config::load(None).expect("defaults");
        let dir = tempfile::tempdir().expect("temp dir");
        config.server.data_dir = dir.path().to_path_buf();
        config.server.http = "127.0.0.1:0".into();
        config.server.flow_tcp = "127.0.0.1:0".into();
        let options = Options { from: None, args };
        let findings = examine(&config, &options, &[&Counted]);
        assert_eq!(findings[0], Finding::ok("widgets", "3 widgets"));
        assert!(findings.iter().any(|f| f.check == "ports"), "{findings:?}");
        assert!(findings.iter().all(|f| f.check != "models"), "{findings:?}");
    }
}
