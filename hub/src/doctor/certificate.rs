//! The doctor's HTTPS check: when `[http] tls` is on, the certificate exists and parses, and a self-signed one
//! names every address and host name of this machine (else browsers reaching it by a new address refuse it).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use tokio_rustls::rustls::pki_types::CertificateDer;
use tokio_rustls::rustls::pki_types::pem::PemObject;

use super::finding::Finding;
use crate::config::Config;
use crate::http::tls::machine_names;

/// The facts about the certificate.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Facts {
    /// HTTPS is off.
    Off,
    /// The agent makes the certificate itself (`tls = "self-signed"`).
    SelfSigned {
        cert: PathBuf,
        /// How many certificates the PEM file holds, or why it could not be read (`None`: no file yet).
        parsed: Option<Result<usize, String>>,
        /// The names the certificate was made for (its `names.txt`).
        names: BTreeSet<String>,
        /// The names this machine has now.
        wanted: BTreeSet<String>,
    },
    /// The user's own certificate (`tls = "files"`).
    Files {
        cert: PathBuf,
        parsed: Option<Result<usize, String>>,
    },
}

fn parse(cert: &Path) -> Option<Result<usize, String>> {
    if !cert.exists() {
        return None;
    }
    Some(
        CertificateDer::pem_file_iter(cert)
            .map_err(|e| e.to_string())
            .and_then(|certs| {
                certs
                    .collect::<Result<Vec<_>, _>>()
                    .map_err(|e| e.to_string())
            })
            .map(|certs| certs.len()),
    )
}

/// Gathers the facts the configuration points at.
pub fn gather(config: &Config) -> Facts {
    let data = &config.server.data_dir;
    match config.http.tls.as_str() {
        "self-signed" => {
            let dir = data.join("tls");
            let cert = dir.join("cert.pem");
            let names = std::fs::read_to_string(dir.join("names.txt"))
                .map(|t| t.lines().map(str::to_string).collect())
                .unwrap_or_default();
            Facts::SelfSigned {
                parsed: parse(&cert),
                cert,
                names,
                wanted: machine_names(&config.http.allowed_hosts),
            }
        }
        "files" => {
            let file = Path::new(&config.http.tls_cert);
            let cert = if file.is_absolute() {
                file.to_path_buf()
            } else {
                data.join(file)
            };
            Facts::Files {
                parsed: parse(&cert),
                cert,
            }
        }
        _ => Facts::Off,
    }
}

/// Whether a certificate made for `names` names `name` (a host name in any case, or an address), so that a browser
/// opening the page by `name` accepts it.
pub fn names_name(names: &BTreeSet<String>, name: &str) -> bool {
    names.iter().any(|n| n.eq_ignore_ascii_case(name))
}

/// The findings for the certificate (none when HTTPS is off).
pub fn findings(facts: &Facts) -> Vec<Finding> {
    let unreadable = |cert: &Path, why: &str, fix: &str| {
        Finding::problem(
            "tls",
            format!(
                "{} does not parse as a PEM certificate: {why}",
                cert.display()
            ),
            fix.to_string(),
        )
    };
    match facts {
        Facts::Off => Vec::new(),
        Facts::SelfSigned {
            cert,
            parsed,
            names,
            wanted,
        } => match parsed {
            None => vec![Finding::ok(
                "tls",
                format!(
                    "{} does not exist yet; the agent makes it at start",
                    cert.display()
                ),
            )],
            Some(Err(why)) => vec![unreadable(
                cert,
                why,
                "delete the data directory's tls folder; the agent makes a new certificate at start",
            )],
            Some(Ok(_)) => {
                let missing: Vec<&str> = wanted
                    .iter()
                    .filter(|w| !names_name(names, w))
                    .map(String::as_str)
                    .collect();
                if missing.is_empty() {
                    vec![Finding::ok(
                        "tls",
                        format!("{} names every address of this machine", cert.display()),
                    )]
                } else {
                    vec![Finding::warning(
                        "tls",
                        format!(
                            "{} does not name {}: a browser reaching the agent by that name refuses it",
                            cert.display(),
                            missing.join(", ")
                        ),
                        "restart robot-agent: it makes a new certificate for this machine's names (browsers ask \
                         to accept it again)",
                    )]
                }
            }
        },
        Facts::Files { cert, parsed } => match parsed {
            None => vec![Finding::problem(
                "tls",
                format!("{} is missing", cert.display()),
                "name an existing certificate with --tls-cert or [http] tls_cert",
            )],
            Some(Err(why)) => vec![unreadable(
                cert,
                why,
                "give --tls-cert a PEM certificate chain",
            )],
            Some(Ok(0)) => vec![unreadable(
                cert,
                "it holds no certificate",
                "give --tls-cert a PEM certificate chain",
            )],
            Some(Ok(n)) => vec![Finding::ok(
                "tls",
                format!(
                    "{} parses as PEM ({n} certificates); the doctor does not check the names of a certificate \
                     of your own",
                    cert.display()
                ),
            )],
        },
    }
}

/// Gathers the facts and makes the findings.
pub fn check(config: &Config) -> Vec<Finding> {
    findings(&gather(config))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::doctor::Level;

    fn names(list: &[&str]) -> BTreeSet<String> {
        list.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn a_certificate_without_an_address_of_the_machine_names_the_address_and_the_fix() {
        let f = findings(&Facts::SelfSigned {
            cert: "/d/tls/cert.pem".into(),
            parsed: Some(Ok(1)),
            names: names(&["localhost", "127.0.0.1"]),
            wanted: names(&["localhost", "127.0.0.1", "192.168.1.20"]),
        });
        assert_eq!(f.len(), 1);
        assert_eq!(f[0].level, Level::Warning);
        assert!(f[0].text.contains("192.168.1.20"), "{}", f[0]);
        assert!(!f[0].text.contains("localhost"), "{}", f[0]);
        assert!(
            f[0].fix.as_deref().unwrap_or("").contains("restart"),
            "{}",
            f[0]
        );
    }

    #[test]
    fn a_certificate_naming_every_address_is_fine() {
        let all = names(&["localhost", "10.0.0.2"]);
        let f = findings(&Facts::SelfSigned {
            cert: "/d/tls/cert.pem".into(),
            parsed: Some(Ok(1)),
            names: all.clone(),
            wanted: all,
        });
        assert_eq!(f[0].level, Level::Ok);
    }

    #[test]
    fn a_missing_certificate_of_your_own_is_a_problem() {
        let f = findings(&Facts::Files {
            cert: "/etc/cert.pem".into(),
            parsed: None,
        });
        assert_eq!(f[0].level, Level::Problem);
        assert!(f[0].fix.as_deref().unwrap_or("").contains("--tls-cert"));
    }

    #[test]
    fn a_file_that_is_not_pem_is_a_problem() {
        let dir = tempfile::tempdir().expect("temp dir");
        let cert = dir.path().join("cert.pem");
        std::fs::write(&cert, "not a certificate").expect("write");
        let f = findings(&Facts::Files {
            parsed: parse(&cert),
            cert,
        });
        assert_eq!(f[0].level, Level::Problem, "{}", f[0]);
    }

    #[test]
    fn a_name_is_found_in_any_case() {
        let made = names(&["robot.local", "192.168.1.20"]);
        assert!(names_name(&made, "Robot.Local"));
        assert!(names_name(&made, "192.168.1.20"));
        assert!(!names_name(&made, "robot"));
    }

    #[test]
    fn nothing_is_said_when_https_is_off() {
        assert!(findings(&Facts::Off).is_empty());
    }
}
