//! Two network namespaces joined by a veth pair, made by a test (`ip netns`, which needs root or `CAP_NET_ADMIN`),
//! so that processes on either side talk over a real network link that the test can cut and mend. Each side has
//! its loopback up (servers there still bind 127.0.0.1) and one address on the pair; Unix sockets, which live in
//! the file system, still reach the processes from the test's own namespace.

use std::process::Command;

use anyhow::{Context, bail};

/// The pair; both namespaces (and the veth pair with them) are deleted when it is dropped.
#[derive(Debug)]
pub struct NetnsPair {
    /// The namespaces' names, for `AgentOptions::netns`.
    pub a: String,
    pub b: String,
    /// The addresses of the two ends of the link, in `a` and in `b`.
    pub addr_a: String,
    pub addr_b: String,
    veth_a: String,
}

/// Runs `ip` with `args`, failing with what it printed.
fn ip(args: &[&str]) -> anyhow::Result<()> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .context("running ip (iproute2)")?;
    if !out.status.success() {
        bail!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    Ok(())
}

impl NetnsPair {
    /// Makes the pair, or returns why this machine does not allow it (no `ip`, not root, no namespaces), so that
    /// the caller can say so and skip.
    pub fn create() -> Result<NetnsPair, String> {
        // Names and addresses from the process id, so that concurrent test runs on one machine do not collide.
        let id = std::process::id();
        let subnet = id % 250 + 1;
        let pair = NetnsPair {
            a: format!("flowtest-{id}-a"),
            b: format!("flowtest-{id}-b"),
            addr_a: format!("10.231.{subnet}.1"),
            addr_b: format!("10.231.{subnet}.2"),
            veth_a: format!("vft{id}a"),
        };
        // Made before any step can fail, so that Drop cleans up whatever was made.
        if let Err(e) = ip(&["netns", "add", &pair.a]) {
            return Err(format!("{e:#}"));
        }
        pair.wire().map_err(|e| format!("{e:#}"))?;
        Ok(pair)
    }

    fn wire(&self) -> anyhow::Result<()> {
        let veth_b = format!("{}b", &self.veth_a[..self.veth_a.len() - 1]);
        ip(&["netns", "add", &self.b])?;
        ip(&[
            "link",
            "add",
            &self.veth_a,
            "type",
            "veth",
            "peer",
            "name",
            &veth_b,
        ])?;
        ip(&["link", "set", &self.veth_a, "netns", &self.a])?;
        ip(&["link", "set", &veth_b, "netns", &self.b])?;
        for (ns, dev, addr) in [
            (&self.a, &self.veth_a, &self.addr_a),
            (&self.b, &veth_b, &self.addr_b),
        ] {
            ip(&["-n", ns, "addr", "add", &format!("{addr}/24"), "dev", dev])?;
            ip(&["-n", ns, "link", "set", dev, "up"])?;
            ip(&["-n", ns, "link", "set", "lo", "up"])?;
        }
        Ok(())
    }

    /// Takes the link down (`false`: nothing crosses, as if the cable were pulled) or up again.
    pub fn set_link(&self, up: bool) -> anyhow::Result<()> {
        ip(&[
            "-n",
            &self.a,
            "link",
            "set",
            &self.veth_a,
            if up { "up" } else { "down" },
        ])
    }
}

impl Drop for NetnsPair {
    fn drop(&mut self) {
        // Deleting a namespace deletes the veth end inside it, and with it the other end.
        let _ = ip(&["netns", "del", &self.a]);
        let _ = ip(&["netns", "del", &self.b]);
    }
}
