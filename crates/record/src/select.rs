//! Which channels a recording or a replay takes (glob patterns over channel names) and under which names a
//! replay publishes them (`OLD=NEW` remaps).

use crate::error::RecordError;

/// Channel-name globs (`*`, `?`, `[...]`); no pattern means every channel.
#[derive(Debug, Clone, Default)]
pub struct Selection {
    patterns: Vec<glob::Pattern>,
}

impl Selection {
    pub fn new<S: AsRef<str>>(patterns: &[S]) -> Result<Selection, RecordError> {
        let patterns = patterns
            .iter()
            .map(|p| {
                glob::Pattern::new(p.as_ref()).map_err(|e| RecordError::Pattern {
                    pattern: p.as_ref().to_string(),
                    reason: e.to_string(),
                })
            })
            .collect::<Result<_, _>>()?;
        Ok(Selection { patterns })
    }

    pub fn matches(&self, name: &str) -> bool {
        self.patterns.is_empty() || self.patterns.iter().any(|p| p.matches(name))
    }
}

/// Exact-name renames for replay.
#[derive(Debug, Clone, Default)]
pub struct Remap {
    pairs: Vec<(String, String)>,
}

impl Remap {
    /// Parses `OLD=NEW` pairs.
    pub fn new<S: AsRef<str>>(pairs: &[S]) -> Result<Remap, RecordError> {
        let pairs = pairs
            .iter()
            .map(|p| {
                let text = p.as_ref();
                match text.split_once('=') {
                    Some((old, new)) if !old.is_empty() && !new.is_empty() => {
                        Ok((old.to_string(), new.to_string()))
                    }
                    _ => Err(RecordError::Remap(text.to_string())),
                }
            })
            .collect::<Result<_, _>>()?;
        Ok(Remap { pairs })
    }

    /// The name to publish `name` under.
    pub fn apply<'a>(&'a self, name: &'a str) -> &'a str {
        self.pairs
            .iter()
            .find(|(old, _)| old == name)
            .map_or(name, |(_, new)| new.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_pattern_selects_everything_and_globs_select_by_name() {
        assert!(Selection::new::<&str>(&[]).expect("empty").matches("A.b"));
        let s = Selection::new(&["Cam.video*", "X.?"]).expect("valid");
        assert!(s.matches("Cam.video") && s.matches("Cam.video.y") && s.matches("X.a"));
        assert!(!s.matches("Cam.audio") && !s.matches("X.ab"));
        assert!(Selection::new(&["[a"]).is_err());
    }

    #[test]
    fn a_remap_renames_only_its_exact_name() {
        let r = Remap::new(&["A.b=C.d"]).expect("valid");
        assert_eq!(r.apply("A.b"), "C.d");
        assert_eq!(r.apply("A.bc"), "A.bc");
        assert!(Remap::new(&["nonsense"]).is_err());
        assert!(Remap::new(&["=x"]).is_err());
    }
}
