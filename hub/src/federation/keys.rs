//! How hub channels are named on Zenoh: the pure mapping between a channel of a hub and the key expressions that
//! carry its data, announce it and describe it (docs/federation.md, "Keys").
//!
//! ```text
//! <prefix>/<hub>/<channel>                     stream data (put), or the service (queryable)
//! <prefix>/@flow/<hub>/stream/<channel>        liveliness token: the hub exports this stream
//! <prefix>/@flow/<hub>/service/<channel>       liveliness token: the hub exports this service
//! <prefix>/@header/<hub>/<channel>             the channel's JSON header (queryable, and a put on each change)
//! ```
//!
//! The `@` chunks are verbatim in Zenoh: a wildcard never matches them, so a client subscribing to
//! `<prefix>/*/Agent.transcript` gets data, never announcements or headers.

use flow::ChannelKind;

use crate::zenoh_names::{KeyError, check_literal};

/// One federation's key space: the prefix every key starts with.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Keys {
    prefix: String,
}

/// A channel announced by a hub, read back from its liveliness token.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Announced {
    pub hub: String,
    pub kind: ChannelKind,
    pub channel: String,
}

impl Keys {
    /// `prefix` must pass [`check_literal`].
    pub fn new(prefix: &str) -> Result<Keys, KeyError> {
        check_literal(prefix)?;
        Ok(Keys {
            prefix: prefix.to_string(),
        })
    }

    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// Where a stream's data is put, or where a service is queried.
    pub fn data(&self, hub: &str, channel: &str) -> String {
        format!("{}/{hub}/{channel}", self.prefix)
    }

    /// The liveliness token saying that `hub` exports `channel`.
    pub fn token(&self, hub: &str, kind: ChannelKind, channel: &str) -> String {
        format!("{}/@flow/{hub}/{}/{channel}", self.prefix, kind_word(kind))
    }

    /// Every liveliness token of the federation.
    pub fn all_tokens(&self) -> String {
        format!("{}/@flow/**", self.prefix)
    }

    /// The key of a channel's header.
    pub fn header(&self, hub: &str, channel: &str) -> String {
        format!("{}/@header/{hub}/{channel}", self.prefix)
    }

    /// Every header key of one hub (its queryable).
    pub fn headers_of(&self, hub: &str) -> String {
        format!("{}/@header/{hub}/**", self.prefix)
    }

    /// Every header key of every hub (the importer's subscription to header changes).
    pub fn all_headers(&self) -> String {
        format!("{}/@header/*/**", self.prefix)
    }

    /// Reads a liveliness token's key back; `None` for keys that are not tokens of this prefix.
    pub fn parse_token(&self, key: &str) -> Option<Announced> {
        let rest = key.strip_prefix(&self.prefix)?.strip_prefix("/@flow/")?;
        let (hub, rest) = rest.split_once('/')?;
        let (kind, channel) = rest.split_once('/')?;
        let kind = match kind {
            "stream" => ChannelKind::Stream,
            "service" => ChannelKind::Service,
            _ => return None,
        };
        if hub.is_empty() || channel.is_empty() {
            return None;
        }
        Some(Announced {
            hub: hub.to_string(),
            kind,
            channel: channel.to_string(),
        })
    }

    /// Reads a header key back into (hub, channel).
    pub fn parse_header(&self, key: &str) -> Option<(String, String)> {
        let rest = key.strip_prefix(&self.prefix)?.strip_prefix("/@header/")?;
        let (hub, channel) = rest.split_once('/')?;
        (!hub.is_empty() && !channel.is_empty()).then(|| (hub.to_string(), channel.to_string()))
    }
}

fn kind_word(kind: ChannelKind) -> &'static str {
    match kind {
        ChannelKind::Stream => "stream",
        ChannelKind::Service => "service",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_token_reads_back_as_the_channel_it_announces() {
        let keys = Keys::new("flow/lab").expect("prefix");
        for (hub, kind, channel) in [
            ("a", ChannelKind::Stream, "Robot.transcript"),
            ("hub-2", ChannelKind::Service, "Robot.ask"),
            ("b", ChannelKind::Stream, "robot/arm/joints"),
        ] {
            let key = keys.token(hub, kind, channel);
            let back = keys.parse_token(&key).expect("a token");
            assert_eq!(
                back,
                Announced {
                    hub: hub.into(),
                    kind,
                    channel: channel.into()
                }
            );
        }
        assert_eq!(keys.parse_token("flow/lab/a/Robot.audio"), None);
        assert_eq!(keys.parse_token("other/@flow/a/stream/x"), None);
        assert_eq!(keys.parse_token("flow/lab/@flow/a/queue/x"), None);
    }

    #[test]
    fn data_keys_are_prefix_hub_and_channel() {
        let keys = Keys::new("flow").expect("prefix");
        assert_eq!(keys.data("a", "Robot.audio"), "flow/a/Robot.audio");
        assert_eq!(
            keys.parse_header(&keys.header("a", "Robot.audio")),
            Some(("a".into(), "Robot.audio".into()))
        );
    }
}
