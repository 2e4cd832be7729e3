//! Identities and topic names. Topics are namespaced by rover name (`rover1/scan`); a command
//! only ever goes to the namespace of the rover it is meant for.

use serde::{Deserialize, Serialize};
use std::fmt;

/// A rover's number in the fleet; its namespace is `rover{n}`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct RoverId(pub u8);

impl RoverId {
    /// The rover's namespace, e.g. `rover2`.
    pub fn namespace(&self) -> String {
        format!("rover{}", self.0)
    }

    /// A topic inside this rover's namespace: `rover2/` + `name`.
    pub fn topic(&self, name: &str) -> Topic {
        Topic(format!("rover{}/{}", self.0, name))
    }

    /// Parses `rover<n>` as written in scenario files and topic prefixes.
    pub fn parse(s: &str) -> Option<RoverId> {
        let n = s.strip_prefix("rover")?;
        if n.is_empty() || !n.bytes().all(|b| b.is_ascii_digit()) || n.starts_with('0') {
            return None;
        }
        n.parse().ok().map(RoverId)
    }
}

impl fmt::Display for RoverId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "rover{}", self.0)
    }
}

/// A topic key such as `rover1/scan` or `lander/map/merged`.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct Topic(pub String);

impl Topic {
    /// A topic from its full key.
    pub fn new(key: impl Into<String>) -> Self {
        Topic(key.into())
    }

    /// The full key.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The rover whose namespace this topic is in, if any.
    pub fn rover(&self) -> Option<RoverId> {
        RoverId::parse(self.0.split('/').next()?)
    }

    /// The part after the namespace: `scan` for `rover1/scan`.
    pub fn leaf(&self) -> &str {
        self.0
            .split_once('/')
            .map_or(self.0.as_str(), |(_, rest)| rest)
    }
}

impl fmt::Display for Topic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topics_carry_their_namespace() {
        let t = RoverId(2).topic("map/delta");
        assert_eq!(t.as_str(), "rover2/map/delta");
        assert_eq!(t.rover(), Some(RoverId(2)));
        assert_eq!(t.leaf(), "map/delta");
        assert_eq!(Topic::new("lander/map").rover(), None);
        assert_eq!(RoverId::parse("rover07"), None);
        assert_eq!(RoverId::parse("rover12"), Some(RoverId(12)));
    }
}
