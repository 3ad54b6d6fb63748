//! The knowledge folder on the brain's side (`[agent] knowledge`, docs/knowledge.md): opened at start, opened again
//! on the watcher's thread whenever the folder changes (the brain swaps the new index in between two steps), and
//! asked for the passages of a chat turn's facts and for what `recall(T)` says.

use std::cell::RefCell;
use std::path::PathBuf;
use std::sync::Arc;

use agent_contract::chat::Passage;
use agent_knowledge::{
    Candidate, FolderWatch, Hit, Knowledge, KnowledgeError, Language, MIN_COVERAGE,
};
use tokio::sync::mpsc;
use tracing::{info, warn};

/// Indexes waiting to be swapped in: the latest one is all that matters.
const UPDATES: usize = 2;

/// The index the brain reads.
#[derive(Debug)]
pub struct Shelf {
    current: Arc<Knowledge>,
    /// The last question searched and its candidate: one question is asked for up to three times (the `known`
    /// percept, then `recall(T)` or a chat turn's facts; the pause's trial step before them).
    last: RefCell<Option<(String, Option<Candidate>)>>,
}

/// The indexes the watcher makes, for the brain's loop to swap in.
#[derive(Debug)]
pub struct Updates {
    updates: mpsc::Receiver<Result<Knowledge, KnowledgeError>>,
    /// Watching ends when this is dropped (the module stops).
    _watch: Option<FolderWatch>,
}

impl Updates {
    /// The next index the watcher made (pending forever without a folder).
    pub async fn next(&mut self) -> Option<Result<Knowledge, KnowledgeError>> {
        match self._watch {
            Some(_) => self.updates.recv().await,
            None => std::future::pending().await,
        }
    }
}

impl Shelf {
    /// The folder opened (on a blocking thread) and watched; none configured, an empty shelf. A folder that does
    /// not exist yet is empty until it appears; a path that is not a folder fails, naming it.
    pub async fn open(
        dir: Option<PathBuf>,
        language: Language,
    ) -> anyhow::Result<(Shelf, Updates)> {
        let (tx, updates) = mpsc::channel(UPDATES);
        let Some(dir) = dir else {
            let shelf = Shelf::holding(Knowledge::empty(language));
            return Ok((
                shelf,
                Updates {
                    updates,
                    _watch: None,
                },
            ));
        };
        let first = dir.clone();
        let knowledge =
            tokio::task::spawn_blocking(move || Knowledge::open(&first, language)).await??;
        info!(
            folder = %dir.display(),
            files = knowledge.files(),
            passages = knowledge.passages(),
            skipped = knowledge.skipped().len(),
            "brain: the knowledge folder is indexed"
        );
        let again = dir.clone();
        let watched = agent_knowledge::watch(&dir, move || {
            // The watcher's own thread indexes, at background priority: the turn goes first.
            let _ = flow::priority::lower_this_thread(flow::priority::BACKGROUND_NICE);
            // A full queue already holds a newer index to swap in, or one about to be replaced.
            let _ = tx.try_send(Knowledge::open(&again, language));
        });
        // The folder is indexed; without a watch (the machine's inotify instances used up) it is only not indexed
        // again, which is no reason to stop answering.
        let watch = match watched {
            Ok(watch) => Some(watch),
            Err(e) => {
                warn!(folder = %dir.display(), "brain: the knowledge folder is not watched, a change needs a restart: {e}");
                None
            }
        };
        let shelf = Shelf::holding(knowledge);
        Ok((
            shelf,
            Updates {
                updates,
                _watch: watch,
            },
        ))
    }

    fn holding(knowledge: Knowledge) -> Shelf {
        Shelf {
            current: Arc::new(knowledge),
            last: RefCell::new(None),
        }
    }

    /// The passage that best covers `question`, searched once per question.
    fn candidate(&self, question: &str) -> Option<Candidate> {
        if let Some((asked, candidate)) = self.last.borrow().as_ref()
            && asked == question
        {
            return candidate.clone();
        }
        let candidate = self.current.candidate(question);
        *self.last.borrow_mut() = Some((question.to_owned(), candidate.clone()));
        candidate
    }

    /// Swaps a new index in; a folder that no longer opens keeps the previous index (logged).
    pub fn swap(&mut self, update: Result<Knowledge, KnowledgeError>) {
        match update {
            Ok(knowledge) => {
                info!(
                    files = knowledge.files(),
                    passages = knowledge.passages(),
                    "brain: the knowledge folder changed and is indexed again"
                );
                *self = Shelf::holding(knowledge);
            }
            Err(e) => warn!(
                "brain: the changed knowledge folder does not open, the previous index stays: {e}"
            ),
        }
    }

    /// The passage sure enough to be said for `question`, if any.
    pub fn recall(&self, question: &str) -> Option<Hit> {
        self.candidate(question)
            .filter(Candidate::is_confident)
            .map(|c| c.hit)
    }

    /// The passages a chat turn's facts carry: the best one when it covers enough of the question
    /// ([`MIN_COVERAGE`]), even on one shared word, since the model judges whether it is relevant (`recall` asks
    /// for more). Only that one, since every token of the prompt costs the small model time before its first word,
    /// and none for a question the folder is not about.
    pub fn passages(&self, question: &str) -> Vec<Passage> {
        self.candidate(question)
            .filter(|c| c.coverage >= MIN_COVERAGE)
            .map(|c| Passage {
                file: c.hit.file,
                text: c.hit.text,
            })
            .into_iter()
            .collect()
    }
}
