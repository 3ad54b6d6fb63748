//! The agent's knowledge folder: Markdown and text files cut into passages, indexed with tantivy (BM25) in RAM,
//! searched by a spoken question; [`Knowledge::best`] gives the one passage sure enough to be said by a rule with
//! no language model, and [`watch`] tells the owner when the folder changed so that it opens it again
//! (docs/knowledge.md).
//!
//! ```no_run
//! use agent_knowledge::{Knowledge, Language};
//! let knowledge = Knowledge::open("knowledge/", Language::En)?;
//! if let Some(hit) = knowledge.best("what do you store about me?") {
//!     println!("{} ({}): {}", hit.file, hit.heading, hit.text);
//! }
//! let _watch = agent_knowledge::watch("knowledge/", || { /* open it again on a blocking thread, swap */ })?;
//! # Ok::<(), agent_knowledge::KnowledgeError>(())
//! ```

mod confidence;
mod error;
mod folder;
mod index;
mod markup;
mod passage;
mod watch;
mod words;

use std::collections::HashSet;
use std::path::{Path, PathBuf};

pub use confidence::{CANDIDATES, MIN_COVERAGE, MIN_MATCHED};
pub use error::KnowledgeError;
pub use folder::{MAX_FILE_BYTES, SkipReason, Skipped};
pub use passage::{HEADING_SEPARATOR, MAX_CHARS};
pub use watch::{DEBOUNCE, FolderWatch, watch};
pub use words::Language;

use confidence::Weighted;
use passage::Passage;

/// A passage found for a question.
#[derive(Debug, Clone, PartialEq)]
pub struct Hit {
    /// The file, relative to the folder, `/`-separated.
    pub file: String,
    /// The headings above the passage ("Commands > Looking around"), empty when there are none.
    pub heading: String,
    /// The passage as plain text to speak, at most [`MAX_CHARS`] characters.
    pub text: String,
    /// BM25 score: comparable between the hits of one question only.
    pub score: f32,
}

/// The passage that best covers a question, and how much of it.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    pub hit: Hit,
    /// The share (0 to 1) of the question's weighted content terms the passage has (`confidence.rs`).
    pub coverage: f32,
    /// How many of the question's distinct content terms the passage has.
    pub matched: usize,
}

impl Candidate {
    /// Sure enough to be said as the answer ([`Knowledge::best`]).
    pub fn is_confident(&self) -> bool {
        confidence::is_confident(self.coverage, self.matched)
    }
}

/// A folder's passages and their index, read-only: share it behind an `Arc` and swap in a new one when
/// [`watch`] reports a change.
pub struct Knowledge {
    dir: PathBuf,
    language: Language,
    passages: Vec<Passage>,
    /// Each passage's terms (heading path, file name and text), for the confidence rule.
    terms: Vec<HashSet<String>>,
    /// `None` for a folder without passages.
    index: Option<index::Index>,
    files: usize,
    skipped: Vec<Skipped>,
}

impl std::fmt::Debug for Knowledge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Knowledge")
            .field("dir", &self.dir)
            .field("language", &self.language)
            .field("files", &self.files)
            .field("passages", &self.passages.len())
            .field("skipped", &self.skipped)
            .finish()
    }
}

impl Knowledge {
    /// Reads and indexes every `.md` and `.txt` file under `dir` (blocking: call it on a blocking thread). A
    /// folder that does not exist yet, or has no such files, gives an empty knowledge; a path that is not a
    /// directory, or a folder that cannot be listed, is an error naming it.
    pub fn open(dir: impl AsRef<Path>, language: Language) -> Result<Knowledge, KnowledgeError> {
        let dir = dir.as_ref();
        let listing = folder::read(dir)?;
        let passages: Vec<Passage> = listing.files.iter().flat_map(passage::split).collect();
        let mut analyzer = words::analyzer(language);
        let headings: Vec<String> = passages.iter().map(heading_words).collect();
        let terms = passages
            .iter()
            .map(|p| {
                // The whole heading path counts for coverage: "Commands > Time" is about commands too.
                let mut set: HashSet<String> = words::terms(&mut analyzer, &p.heading)
                    .into_iter()
                    .collect();
                set.extend(words::terms(&mut analyzer, &file_words(&p.file)));
                set.extend(words::terms(&mut analyzer, &p.text));
                set
            })
            .collect();
        let index = if passages.is_empty() {
            None
        } else {
            let documents: Vec<index::Document<'_>> = passages
                .iter()
                .zip(&headings)
                .map(|(p, h)| index::Document {
                    heading: h,
                    body: &p.text,
                })
                .collect();
            Some(index::Index::build(&documents, analyzer).map_err(|source| {
                KnowledgeError::Index {
                    path: dir.to_path_buf(),
                    source,
                }
            })?)
        };
        Ok(Knowledge {
            dir: dir.to_path_buf(),
            language,
            passages,
            terms,
            index,
            files: listing.files.len(),
            skipped: listing.skipped,
        })
    }

    /// Knowledge with nothing in it, for an owner that has not opened its folder yet.
    pub fn empty(language: Language) -> Knowledge {
        Knowledge {
            dir: PathBuf::new(),
            language,
            passages: Vec::new(),
            terms: Vec::new(),
            index: None,
            files: 0,
            skipped: Vec::new(),
        }
    }

    /// The `limit` passages that best match `question`, best first; none for a question made only of stop words
    /// or an empty folder. The index is in RAM, so a search does no I/O and is not expected to fail; if tantivy
    /// ever reports an error it is treated as no hits.
    pub fn search(&self, question: &str, limit: usize) -> Vec<Hit> {
        self.ranked(question, limit)
            .into_iter()
            .map(|(score, id)| self.hit(id, score))
            .collect()
    }

    /// The passage confident enough to be the answer, or `None`: among the [`CANDIDATES`] best hits, the first
    /// with the highest coverage of the question's content, if that reaches [`MIN_COVERAGE`]
    /// (`confidence.rs`, docs/knowledge.md).
    pub fn best(&self, question: &str) -> Option<Hit> {
        self.candidate(question)
            .filter(Candidate::is_confident)
            .map(|c| c.hit)
    }

    /// The passage [`Knowledge::best`] would weigh, with its coverage, whether or not it reaches the bar: for
    /// logs and for calibrating the rule.
    pub fn candidate(&self, question: &str) -> Option<Candidate> {
        let index = self.index.as_ref()?;
        let mut analyzer = words::analyzer(self.language);
        let terms = words::distinct_terms(&mut analyzer, question);
        if terms.is_empty() {
            return None;
        }
        let weighted: Vec<Weighted> = terms
            .iter()
            .map(|t| Weighted {
                term: t.clone(),
                weight: index.idf(t).unwrap_or(0.0),
            })
            .collect();
        let ranked = index.search(&terms, CANDIDATES).unwrap_or_default();
        let mut best: Option<(f32, f32, usize)> = None;
        for (score, id) in ranked {
            let covered = self
                .terms
                .get(id)
                .map_or(0.0, |set| confidence::coverage(&weighted, set));
            if best.is_none_or(|(c, _, _)| covered > c) {
                best = Some((covered, score, id));
            }
        }
        let (coverage, score, id) = best?;
        let matched = self
            .terms
            .get(id)
            .map_or(0, |set| terms.iter().filter(|t| set.contains(*t)).count());
        Some(Candidate {
            hit: self.hit(id, score),
            coverage,
            matched,
        })
    }

    /// The folder this was read from.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn language(&self) -> Language {
        self.language
    }

    /// How many files were indexed.
    pub fn files(&self) -> usize {
        self.files
    }

    /// How many passages they gave.
    pub fn passages(&self) -> usize {
        self.passages.len()
    }

    /// The files found but not indexed (too large, unreadable), with why.
    pub fn skipped(&self) -> &[Skipped] {
        &self.skipped
    }

    /// Every passage as a hit with score 0, in file order: for a baseline or a listing.
    pub fn all(&self) -> Vec<Hit> {
        (0..self.passages.len())
            .map(|id| self.hit(id, 0.0))
            .collect()
    }

    fn ranked(&self, question: &str, limit: usize) -> Vec<(f32, usize)> {
        let Some(index) = &self.index else {
            return Vec::new();
        };
        let mut analyzer = words::analyzer(self.language);
        let terms = words::distinct_terms(&mut analyzer, question);
        index.search(&terms, limit).unwrap_or_default()
    }

    fn hit(&self, id: usize, score: f32) -> Hit {
        match self.passages.get(id) {
            Some(p) => Hit {
                file: p.file.clone(),
                heading: p.heading.clone(),
                text: p.text.clone(),
                score,
            },
            None => Hit {
                file: String::new(),
                heading: String::new(),
                text: String::new(),
                score,
            },
        }
    }
}

/// What a passage's heading field holds: its own (deepest) heading and its file's name as words, so that a text
/// file without headings is still found by its name. Only the deepest heading: every section under "What I can
/// do" would otherwise match "what can you do" as well as the section that answers it.
fn heading_words(p: &Passage) -> String {
    let own = p
        .heading
        .rsplit(HEADING_SEPARATOR)
        .next()
        .unwrap_or(&p.heading);
    format!("{own} {}", file_words(&p.file))
}

/// A file's name as words: "visits/opening-hours.txt" -> "opening hours".
fn file_words(file: &str) -> String {
    let name = file.rsplit('/').next().unwrap_or(file);
    let stem = name.rsplit_once('.').map_or(name, |(s, _)| s);
    stem.replace(['-', '_'], " ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn folder(files: &[(&str, &str)]) -> tempfile::TempDir {
        let dir = tempfile::tempdir().expect("tempdir");
        for (name, text) in files {
            let path = dir.path().join(name);
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent).expect("mkdir");
            }
            std::fs::write(path, text).expect("write");
        }
        dir
    }

    fn sample() -> tempfile::TempDir {
        folder(&[
            (
                "privacy.md",
                "# Privacy\n\nI keep no recordings of your voice. The camera images are not stored.\n\n\
                 ## Conversation\n\nThe last turns of our conversation are kept so that I can follow it.\n",
            ),
            (
                "commands.md",
                "# Commands\n\n## Looking around\n\nAsk me what I see, and I tell you how many people are \
                 in front of me.\n\n## Time\n\nAsk me the time or the date.\n",
            ),
            (
                "visits/opening-hours.txt",
                "We open at nine and close at six.\n",
            ),
        ])
    }

    #[test]
    fn search_finds_the_file_about_the_question() {
        let dir = sample();
        let k = Knowledge::open(dir.path(), Language::En).expect("open");
        assert_eq!(k.files(), 3);
        let hits = k.search("Do you store recordings of my voice?", 3);
        assert_eq!(hits[0].file, "privacy.md");
        assert_eq!(hits[0].heading, "Privacy");
        let hits = k.search("how many people can you see", 3);
        assert_eq!(hits[0].file, "commands.md");
        assert_eq!(hits[0].heading, "Commands > Looking around");
        assert!(hits.windows(2).all(|w| w[0].score >= w[1].score));
    }

    #[test]
    fn a_text_file_is_found_by_its_name() {
        let dir = sample();
        let k = Knowledge::open(dir.path(), Language::En).expect("open");
        let hits = k.search("opening hours", 1);
        assert_eq!(hits[0].file, "visits/opening-hours.txt");
    }

    #[test]
    fn best_answers_an_on_topic_question() {
        let dir = sample();
        let k = Knowledge::open(dir.path(), Language::En).expect("open");
        let hit = k.best("Are my voice recordings stored?").expect("on topic");
        assert_eq!(hit.file, "privacy.md");
    }

    #[test]
    fn best_gives_nothing_for_an_off_topic_question() {
        let dir = sample();
        let k = Knowledge::open(dir.path(), Language::En).expect("open");
        for q in [
            "why is the sky blue?",
            "what is the capital of France?",
            "tell me a joke",
            "what?",
        ] {
            assert_eq!(k.best(q), None, "{q}");
        }
    }

    #[test]
    fn a_folder_that_does_not_exist_yet_is_empty_knowledge() {
        let dir = tempfile::tempdir().expect("tempdir");
        let k = Knowledge::open(dir.path().join("later"), Language::En).expect("open");
        assert_eq!(k.passages(), 0);
        assert!(k.search("anything", 3).is_empty());
        assert_eq!(k.best("anything"), None);
    }

    #[test]
    fn a_path_that_is_not_a_directory_is_an_error_naming_it() {
        let dir = sample();
        let err = Knowledge::open(dir.path().join("privacy.md"), Language::En).expect_err("a file");
        assert!(err.to_string().contains("privacy.md"), "{err}");
    }

    #[test]
    fn an_italian_folder_is_searched_with_italian_stems() {
        let dir = folder(&[
            ("comandi.md", "# Comandi\n\nPuoi chiedermi che ore sono.\n"),
            (
                "privacy.md",
                "# Riservatezza\n\nNon registro la tua voce.\n",
            ),
        ]);
        let k = Knowledge::open(dir.path(), Language::It).expect("open");
        let hit = k.best("registri la mia voce?").expect("on topic");
        assert_eq!(hit.file, "privacy.md");
        assert_eq!(k.search("quali comandi capisci?", 1)[0].file, "comandi.md");
    }
}
