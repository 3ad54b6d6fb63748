//! The Zenoh session's configuration from `[federation]`: mode, endpoints, scouting, lease and credentials.

use std::path::Path;

use anyhow::Context;
use serde_json::json;

use crate::config::FederationSection;

/// Builds the Zenoh configuration; `data_dir` resolves relative credential files.
pub fn zenoh_config(f: &FederationSection, data_dir: &Path) -> anyhow::Result<zenoh::Config> {
    let mut c = zenoh::Config::default();
    let mut set = |key: &str, value: serde_json::Value| -> anyhow::Result<()> {
        c.insert_json5(key, &value.to_string())
            .map_err(|e| anyhow::anyhow!("zenoh configuration {key}: {e}"))
    };
    set("mode", json!(f.mode))?;
    set("connect/endpoints", json!(f.connect))?;
    set("listen/endpoints", json!(f.listen))?;
    // A peer that is not there yet is retried in the background: hubs start in any order.
    set("connect/exit_on_failure", json!(false))?;
    set("scouting/multicast/enabled", json!(f.multicast_scouting))?;
    set("transport/link/tx/lease", json!(f.lease_ms))?;
    // Streams go out with congestion control `Drop`; Zenoh waits this long (µs) for a free batch before dropping a
    // sample, 1 ms by default. A scheduler hiccup on a loaded machine is longer than that, and the exporter waits on
    // a task of its own, never on the hub's fan-out thread, so a few milliseconds more cost no one: samples are
    // dropped when the network is congested, not when a core is busy for a moment.
    set(
        "transport/link/tx/queue/congestion_control/drop/wait_before_drop",
        json!(5000),
    )?;
    if !f.user.is_empty() {
        let path = resolve(data_dir, &f.password_file);
        let password = std::fs::read_to_string(&path)
            .with_context(|| format!("federation.password_file: reading {}", path.display()))?;
        set("transport/auth/usrpwd/user", json!(f.user))?;
        set("transport/auth/usrpwd/password", json!(password.trim()))?;
    }
    if !f.users_file.is_empty() {
        let path = resolve(data_dir, &f.users_file);
        std::fs::metadata(&path)
            .with_context(|| format!("federation.users_file: reading {}", path.display()))?;
        set(
            "transport/auth/usrpwd/dictionary_file",
            json!(path.display().to_string()),
        )?;
    }
    Ok(c)
}

fn resolve(data_dir: &Path, file: &str) -> std::path::PathBuf {
    let p = Path::new(file);
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        data_dir.join(p)
    }
}
