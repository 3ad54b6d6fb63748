//! HTTPS for the page (`[http] tls`): a browser on another machine gives the microphone and camera only to a secure
//! page. The certificate is the user's (`tls = "files"`) or made once into `data_dir/tls/` for this machine's host
//! names and addresses (`"self-signed"`); either way its SHA-256 fingerprint is printed beside the URL, so that the
//! user can compare it with the one the browser's warning page shows before accepting the certificate.

use std::collections::BTreeSet;
use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use sha2::{Digest, Sha256};
use thiserror::Error;
use tokio_rustls::TlsAcceptor;
use tokio_rustls::rustls::ServerConfig;
use tokio_rustls::rustls::crypto::ring;
use tokio_rustls::rustls::pki_types::pem::PemObject;
use tokio_rustls::rustls::pki_types::{CertificateDer, PrivateKeyDer};

use crate::config::Config;

/// What went wrong making the TLS set-up, naming the file.
#[derive(Debug, Error)]
pub enum TlsError {
    #[error("{path}: {reason}")]
    File { path: String, reason: String },
    #[error("making the self-signed certificate: {0}")]
    Generate(String),
    #[error("the certificate and key do not make a TLS configuration: {0}")]
    Config(String),
}

fn file_error(path: &Path, reason: impl std::fmt::Display) -> TlsError {
    TlsError::File {
        path: path.display().to_string(),
        reason: reason.to_string(),
    }
}

/// The server's TLS: what accepts connections, and the certificate's fingerprint.
#[derive(Clone)]
pub struct Tls {
    pub acceptor: TlsAcceptor,
    /// SHA-256 of the leaf certificate, as browsers show it (`AB:CD:...`).
    pub fingerprint: String,
    /// The names and addresses a self-signed certificate was made for (empty for the user's own).
    pub names: Vec<String>,
}

impl std::fmt::Debug for Tls {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Tls")
            .field("fingerprint", &self.fingerprint)
            .field("names", &self.names)
            .finish_non_exhaustive()
    }
}

/// The TLS set-up `[http] tls` asks for, or `None` for plain HTTP.
pub fn load(config: &Config) -> Result<Option<Tls>, TlsError> {
    let http = &config.http;
    let data = &config.server.data_dir;
    let (cert, key, names) = match http.tls.as_str() {
        "self-signed" => self_signed(&data.join("tls"), &config.http.allowed_hosts)?,
        "files" => (
            inside(data, &http.tls_cert),
            inside(data, &http.tls_key),
            Vec::new(),
        ),
        _ => return Ok(None),
    };
    let chain: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(&cert)
        .map_err(|e| file_error(&cert, e))?
        .collect::<Result<_, _>>()
        .map_err(|e| file_error(&cert, e))?;
    let Some(leaf) = chain.first() else {
        return Err(file_error(&cert, "holds no certificate"));
    };
    let fingerprint = fingerprint(leaf);
    let key = PrivateKeyDer::from_pem_file(&key).map_err(|e| file_error(&key, e))?;
    // ring rather than rustls's default aws-lc-rs, whose C build needs cmake; rustls marks ring's provider
    // deprecated only because it lacks the post-quantum key exchange, which browsers fall back from.
    #[allow(deprecated)]
    let provider = ring::default_provider();
    let mut server = ServerConfig::builder_with_provider(Arc::new(provider))
        .with_safe_default_protocol_versions()
        .map_err(|e| TlsError::Config(e.to_string()))?
        .with_no_client_auth()
        .with_single_cert(chain, key)
        .map_err(|e| TlsError::Config(e.to_string()))?;
    // The edge speaks HTTP/1.1 only (WebSocket upgrades included).
    server.alpn_protocols = vec![b"http/1.1".to_vec()];
    Ok(Some(Tls {
        acceptor: TlsAcceptor::from(Arc::new(server)),
        fingerprint,
        names,
    }))
}

fn inside(data: &Path, file: &str) -> PathBuf {
    let p = Path::new(file);
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        data.join(p)
    }
}

/// SHA-256 of a certificate in colon-separated upper-case hex, as Chrome and Firefox print it.
pub fn fingerprint(cert: &[u8]) -> String {
    Sha256::digest(cert)
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(":")
}

/// The names this machine is reached by: `localhost`, its host name (with `.local`, as mDNS answers it), the
/// configured `allowed_hosts`, and every address of its interfaces.
pub fn machine_names(allowed_hosts: &[String]) -> BTreeSet<String> {
    let mut names: BTreeSet<String> = ["localhost".to_string()].into();
    let host = rustix::system::uname()
        .nodename()
        .to_string_lossy()
        .into_owned();
    if !host.is_empty() {
        names.insert(format!("{host}.local"));
        names.insert(host);
    }
    names.extend(allowed_hosts.iter().cloned());
    names.extend(["127.0.0.1".to_string(), "::1".to_string()]);
    if let Ok(interfaces) = if_addrs::get_if_addrs() {
        names.extend(interfaces.into_iter().map(|i| i.ip().to_string()));
    }
    names
}

/// The certificate and key made for this machine, made now if absent or if they no longer name every address and
/// host name the machine has (a new network, a renamed host): returns their paths and the names it holds.
fn self_signed(
    dir: &Path,
    allowed_hosts: &[String],
) -> Result<(PathBuf, PathBuf, Vec<String>), TlsError> {
    let cert_path = dir.join("cert.pem");
    let key_path = dir.join("key.pem");
    let names_path = dir.join("names.txt");
    let wanted = machine_names(allowed_hosts);
    let had: BTreeSet<String> = std::fs::read_to_string(&names_path)
        .map(|t| t.lines().map(str::to_string).collect())
        .unwrap_or_default();
    if cert_path.exists() && key_path.exists() && wanted.is_subset(&had) {
        return Ok((cert_path, key_path, had.into_iter().collect()));
    }
    if cert_path.exists() {
        let missing: Vec<&String> = wanted.difference(&had).collect();
        tracing::warn!(
            ?missing,
            "making a new self-signed certificate: the old one does not name every address of this machine \
             (browsers will ask to accept it again)"
        );
    }
    let names: Vec<String> = wanted.iter().cloned().collect();
    let mut params = rcgen::CertificateParams::new(Vec::<String>::new())
        .map_err(|e| TlsError::Generate(e.to_string()))?;
    params.subject_alt_names = names
        .iter()
        .map(|n| match n.parse::<IpAddr>() {
            Ok(ip) => Ok(rcgen::SanType::IpAddress(ip)),
            Err(_) => rcgen::string::Ia5String::try_from(n.as_str())
                .map(rcgen::SanType::DnsName)
                .map_err(|e| TlsError::Generate(format!("{n}: {e}"))),
        })
        .collect::<Result<_, _>>()?;
    params
        .distinguished_name
        .push(rcgen::DnType::CommonName, "robot-agent");
    let key = rcgen::KeyPair::generate().map_err(|e| TlsError::Generate(e.to_string()))?;
    let cert = params
        .self_signed(&key)
        .map_err(|e| TlsError::Generate(e.to_string()))?;
    std::fs::create_dir_all(dir).map_err(|e| file_error(dir, e))?;
    write_private(&key_path, key.serialize_pem().as_bytes())?;
    std::fs::write(&cert_path, cert.pem()).map_err(|e| file_error(&cert_path, e))?;
    std::fs::write(&names_path, names.join("\n")).map_err(|e| file_error(&names_path, e))?;
    tracing::info!(
        cert = %cert_path.display(),
        "made a self-signed certificate for {}",
        names.join(", ")
    );
    Ok((cert_path, key_path, names))
}

/// Writes a file only its owner may read (the private key).
fn write_private(path: &Path, bytes: &[u8]) -> Result<(), TlsError> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(0o600)
        .open(path)
        .map_err(|e| file_error(path, e))?;
    f.write_all(bytes).map_err(|e| file_error(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_self_signed_certificate_is_made_once_and_kept() {
        let dir = tempfile::tempdir().expect("temp dir");
        let (cert, key, _) = self_signed(dir.path(), &["robot.test".into()]).expect("made");
        let first = std::fs::read(&cert).expect("cert");
        self_signed(dir.path(), &["robot.test".into()]).expect("kept");
        assert_eq!(first, std::fs::read(&cert).expect("cert"), "not made again");
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&key).expect("key").permissions().mode();
        assert_eq!(mode & 0o077, 0, "the key is readable by its owner only");
        // A name it lacks makes a new one.
        self_signed(dir.path(), &["other.test".into()]).expect("remade");
        assert_ne!(first, std::fs::read(&cert).expect("cert"));
    }

    #[test]
    fn the_certificate_names_the_machine_and_the_configured_hosts() {
        let dir = tempfile::tempdir().expect("temp dir");
        let (cert, _, names) = self_signed(dir.path(), &["robot.test".into()]).expect("made");
        let der = CertificateDer::from_pem_file(&cert).expect("pem");
        for n in ["localhost", "127.0.0.1", "robot.test"] {
            assert!(names.iter().any(|x| x == n), "{n} missing from {names:?}");
        }
        let fp = fingerprint(&der);
        assert_eq!(fp.len(), 32 * 3 - 1, "{fp}");
    }
}
