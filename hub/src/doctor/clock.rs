//! The doctor's clock check: this machine's clock against the hub's, when a hub answers at the HTTP address (on
//! this machine, or the robot's hub that a satellite's machine names with `--http HOST:PORT`). Satellites stamp
//! spans and transcripts on their own clocks, so a skewed machine puts its work at the wrong time on the hub's
//! timeline. Measured as NTP does: the hub's time against the middle of the request's round trip, whose half is the
//! uncertainty.

use std::net::SocketAddr;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use super::finding::Finding;
use super::ports::{http_request, reachable, resolve};
use crate::config::Config;
use crate::http::HUB_TIME_HEADER;

/// Above this skew the doctor warns: a transcript or span lands visibly off the hub's timeline.
pub const WARN_SKEW: Duration = Duration::from_millis(50);
/// Above this skew it is a problem: stages of one turn come out of order.
pub const PROBLEM_SKEW: Duration = Duration::from_secs(1);
/// How many requests are made: the one with the shortest round trip is kept, as NTP keeps its best sample.
pub const SAMPLES: usize = 3;

/// One request: when it left, the hub's clock while answering it and when the answer came (microseconds since the
/// Unix epoch).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sample {
    pub sent_us: i64,
    pub hub_us: i64,
    pub received_us: i64,
}

impl Sample {
    /// How far the hub's clock is ahead of this machine's (negative: behind).
    pub fn offset_us(&self) -> i64 {
        self.hub_us - (self.sent_us + (self.received_us - self.sent_us) / 2)
    }

    pub fn round_trip_us(&self) -> i64 {
        (self.received_us - self.sent_us).max(0)
    }
}

/// The facts the clock findings are made from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Facts {
    /// The hub was not asked, and why (HTTPS, an address that does not parse).
    NotAsked(String),
    /// No hub answers `/healthz` at the address.
    NoHub(SocketAddr),
    /// A hub answered without its clock: a version from before the header.
    Untold(SocketAddr),
    /// The sample with the shortest round trip.
    Measured(SocketAddr, Sample),
}

fn micros(t: SystemTime) -> i64 {
    t.duration_since(UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_micros()).unwrap_or(i64::MAX))
}

/// Asks the hub at the configured HTTP address for its clock, [`SAMPLES`] times.
pub fn gather(config: &Config) -> Facts {
    if config.http.tls_on() {
        return Facts::NotAsked("HTTPS is on, and the doctor asks over plain HTTP only".into());
    }
    let Some(addr) = resolve(&config.server.http) else {
        return Facts::NotAsked(format!(
            "the HTTP address {:?} is not an address",
            config.server.http
        ));
    };
    let addr = reachable(addr);
    let mut best: Option<Sample> = None;
    for _ in 0..SAMPLES {
        let Some(reply) = http_request(addr, "/healthz", None) else {
            break;
        };
        if reply.status != 200 || reply.body.trim() != "ok" {
            break;
        }
        let Some(hub_us) = reply
            .header(HUB_TIME_HEADER)
            .and_then(|v| v.parse::<i64>().ok())
        else {
            return Facts::Untold(addr);
        };
        let sample = Sample {
            sent_us: micros(reply.sent),
            hub_us,
            received_us: micros(reply.received),
        };
        if best.is_none_or(|b| sample.round_trip_us() < b.round_trip_us()) {
            best = Some(sample);
        }
    }
    best.map_or(Facts::NoHub(addr), |s| Facts::Measured(addr, s))
}

/// A duration in microseconds for people: `850 µs`, `12.3 ms`, `3.20 s`.
fn shown(us: u64) -> String {
    if us < 1_000 {
        format!("{us} µs")
    } else if us < 1_000_000 {
        format!("{:.1} ms", us as f64 / 1e3)
    } else {
        format!("{:.2} s", us as f64 / 1e6)
    }
}

const FIX: &str = "keep both clocks synchronised with NTP: `timedatectl set-ntp true` (systemd-timesyncd) or \
                   chrony, on this machine and the hub's";

/// The finding for the clocks.
pub fn findings(facts: &Facts) -> Vec<Finding> {
    match facts {
        Facts::NotAsked(why) => vec![Finding::ok(
            "clock",
            format!("not compared with the hub's: {why}"),
        )],
        Facts::NoHub(addr) => vec![Finding::ok(
            "clock",
            format!("no hub answers at {addr}: not compared (name the hub with --http HOST:PORT)"),
        )],
        Facts::Untold(addr) => vec![Finding::warning(
            "clock",
            format!(
                "the hub at {addr} does not tell its time (an older version): the clocks' skew cannot be checked"
            ),
            "update robot-agent on the hub's machine; meanwhile keep both clocks synchronised with NTP",
        )],
        Facts::Measured(addr, sample) => {
            let offset = sample.offset_us();
            let uncertainty = sample.round_trip_us().unsigned_abs() / 2;
            // The least skew the measurement allows: a long round trip does not make a skew out of nothing.
            let least = offset.unsigned_abs().saturating_sub(uncertainty);
            let side = if offset >= 0 { "ahead of" } else { "behind" };
            let text = format!(
                "the hub's clock at {addr} is {} ± {} {side} this machine's",
                shown(offset.unsigned_abs()),
                shown(uncertainty)
            );
            let why = "satellites stamp spans and transcripts on their own clock";
            let finding = if least > micros_of(PROBLEM_SKEW) {
                Finding::problem(
                    "clock",
                    format!("{text}, over {}: {why}", shown(micros_of(PROBLEM_SKEW))),
                    FIX,
                )
            } else if least > micros_of(WARN_SKEW) {
                Finding::warning(
                    "clock",
                    format!("{text}, over {}: {why}", shown(micros_of(WARN_SKEW))),
                    FIX,
                )
            } else {
                Finding::ok("clock", text)
            };
            vec![finding]
        }
    }
}

fn micros_of(d: Duration) -> u64 {
    u64::try_from(d.as_micros()).unwrap_or(u64::MAX)
}

/// Asks the hub and makes the finding.
pub fn check(config: &Config) -> Vec<Finding> {
    findings(&gather(config))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::doctor::Level;

    fn addr() -> SocketAddr {
        "192.0.2.7:8080".parse().expect("addr")
    }

    /// A request of 2 ms round trip that the hub answered `skew_us` ahead of this machine.
    fn measured(skew_us: i64) -> Finding {
        let sent_us = 1_700_000_000_000_000;
        let sample = Sample {
            sent_us,
            hub_us: sent_us + 1_000 + skew_us,
            received_us: sent_us + 2_000,
        };
        let f = findings(&Facts::Measured(addr(), sample));
        assert_eq!(f.len(), 1);
        f[0].clone()
    }

    #[test]
    fn the_offset_is_the_hubs_time_against_the_middle_of_the_round_trip() {
        let s = Sample {
            sent_us: 1_000,
            hub_us: 1_600,
            received_us: 2_000,
        };
        assert_eq!(s.offset_us(), 100);
        assert_eq!(s.round_trip_us(), 1_000);
    }

    #[test]
    fn clocks_that_agree_are_fine() {
        let f = measured(0);
        assert_eq!(f.level, Level::Ok, "{f}");
        assert!(f.text.contains("0 µs ± 1.0 ms"), "{f}");
    }

    #[test]
    fn a_skew_of_200_ms_is_a_warning_with_the_fix() {
        let f = measured(200_000);
        assert_eq!(f.level, Level::Warning, "{f}");
        assert!(f.text.contains("200.0 ms ± 1.0 ms ahead of"), "{f}");
        assert!(f.text.contains("satellites stamp"), "{f}");
        let fix = f.fix.as_deref().unwrap_or("");
        assert!(fix.contains("chrony") && fix.contains("timesyncd"), "{f}");
    }

    #[test]
    fn a_skew_of_3_s_is_a_problem() {
        let f = measured(-3_000_000);
        assert_eq!(f.level, Level::Problem, "{f}");
        assert!(f.text.contains("3.00 s ± 1.0 ms behind"), "{f}");
    }

    #[test]
    fn a_skew_within_the_round_trip_is_not_called_a_skew() {
        let sent_us = 0;
        let sample = Sample {
            sent_us,
            hub_us: 300_000,
            received_us: 400_000,
        };
        // 100 ms off the middle, but the answer took 400 ms: the clocks may well agree.
        let f = findings(&Facts::Measured(addr(), sample));
        assert_eq!(f[0].level, Level::Ok, "{}", f[0]);
    }

    #[test]
    fn a_hub_that_does_not_tell_its_time_is_a_warning_that_skew_cannot_be_checked() {
        let f = findings(&Facts::Untold(addr()));
        assert_eq!(f[0].level, Level::Warning, "{}", f[0]);
        assert!(f[0].text.contains("cannot be checked"), "{}", f[0]);
        assert!(f[0].text.contains("older version"), "{}", f[0]);
    }

    #[test]
    fn no_hub_is_said_without_alarm() {
        let f = findings(&Facts::NoHub(addr()));
        assert_eq!(f[0].level, Level::Ok, "{}", f[0]);
        assert!(f[0].text.contains("--http"), "{}", f[0]);
    }
}
