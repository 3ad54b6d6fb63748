//! Claims on utterances: the hub's channel namespace as the lock that gives each utterance to one satellite.
//!
//! A satellite that wants to transcribe an utterance creates the channel `Agent.asr.claim.<id>`. The hub refuses a
//! second channel of the same name, so exactly one satellite succeeds; the hub removes a dead connection's channels
//! and tells everyone, which is how the others learn that a claim was orphaned and the utterance is free again.

/// Prefix of claim channels.
pub const CLAIM_PREFIX: &str = "Agent.asr.claim.";
/// Prefix of the presence channels satellites keep while they run.
pub const PRESENCE_PREFIX: &str = "Agent.asr.sat.";

/// The claim channel of an utterance.
pub fn claim_channel(utterance_id: &str) -> String {
    format!("{CLAIM_PREFIX}{utterance_id}")
}

/// The utterance id of a claim channel name.
pub fn claimed_utterance(channel: &str) -> Option<&str> {
    channel.strip_prefix(CLAIM_PREFIX)
}

/// The JSON header of a claim channel: the interval, so satellites whose segmentation differs slightly can still
/// see that an overlapping utterance is taken. `speculative` marks a claim made when the utterance paused, before
/// it ended (its interval is then the speech so far); it is for people and tests reading the hub, the claim rules
/// do not depend on it.
pub fn claim_header(start_us: u64, end_us: u64, satellite: &str, speculative: bool) -> String {
    let mut header =
        serde_json::json!({ "start_us": start_us, "end_us": end_us, "satellite": satellite });
    if speculative {
        header["speculative"] = serde_json::Value::Bool(true);
    }
    header.to_string()
}

/// The interval in a claim header, if it has one.
pub fn claim_interval(header: &str) -> Option<(u64, u64)> {
    let v: serde_json::Value = serde_json::from_str(header).ok()?;
    Some((v.get("start_us")?.as_u64()?, v.get("end_us")?.as_u64()?))
}

/// True when two intervals share more than `min_us`.
pub fn overlaps(a: (u64, u64), b: (u64, u64), min_us: u64) -> bool {
    let lo = a.0.max(b.0);
    let hi = a.1.min(b.1);
    hi > lo && hi - lo > min_us
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_headers_round_trip() {
        let name = claim_channel("u1700000000123");
        assert_eq!(claimed_utterance(&name), Some("u1700000000123"));
        assert_eq!(claimed_utterance("Agent.audio"), None);
        assert_eq!(
            claim_interval(&claim_header(5, 9, "s1", false)),
            Some((5, 9))
        );
        let speculative = claim_header(5, 9, "s1", true);
        assert_eq!(claim_interval(&speculative), Some((5, 9)));
        assert!(speculative.contains("\"speculative\":true"));
        assert!(!claim_header(5, 9, "s1", false).contains("speculative"));
        assert_eq!(claim_interval("{}"), None);
    }

    #[test]
    fn overlap_needs_a_real_intersection() {
        assert!(overlaps((0, 100), (50, 150), 10));
        assert!(!overlaps((0, 100), (95, 150), 10));
        assert!(!overlaps((0, 100), (100, 150), 0));
    }
}
