//! A generated folder for the costs: files of deterministic pseudo-text (a Zipf-distributed made-up vocabulary,
//! headings and paragraphs) and questions taken from their passages; and the naive baseline, a lowercased
//! substring count of the question's words over every passage.

use std::path::Path;

/// splitmix64: the same folder and questions on every run and machine.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }

    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in `0..n` (`n` > 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }

    /// Uniform in `lo..=hi`.
    pub fn between(&mut self, lo: usize, hi: usize) -> usize {
        lo + self.below(hi - lo + 1)
    }
}

/// Made-up words with Zipf frequencies, as in real text: a few very common, most rare.
pub struct Vocabulary {
    words: Vec<String>,
    /// Cumulative weights 1/rank.
    cumulative: Vec<f64>,
}

const SYLLABLES: &[&str] = &[
    "ka", "lo", "mi", "ne", "ta", "ri", "so", "vu", "pe", "da", "gi", "ho", "ju", "ze", "ba", "fo",
    "ly", "qu", "wa", "xe", "nor", "tal", "vin", "sar", "bel", "dru", "mek", "pol", "rin", "sto",
];

impl Vocabulary {
    pub fn new(size: usize, rng: &mut Rng) -> Vocabulary {
        let mut words = Vec::with_capacity(size);
        let mut seen = std::collections::HashSet::new();
        while words.len() < size {
            let n = rng.between(2, 4);
            let w: String = (0..n)
                .map(|_| SYLLABLES[rng.below(SYLLABLES.len())])
                .collect();
            if seen.insert(w.clone()) {
                words.push(w);
            }
        }
        let mut cumulative = Vec::with_capacity(size);
        let mut total = 0.0;
        for rank in 0..size {
            total += 1.0 / (rank as f64 + 1.0);
            cumulative.push(total);
        }
        Vocabulary { words, cumulative }
    }

    pub fn word(&self, rng: &mut Rng) -> &str {
        let total = self.cumulative.last().copied().unwrap_or(1.0);
        let x = (rng.next() >> 11) as f64 / (1u64 << 53) as f64 * total;
        let i = self.cumulative.partition_point(|c| *c < x);
        &self.words[i.min(self.words.len() - 1)]
    }

    fn sentence(&self, rng: &mut Rng) -> String {
        let n = rng.between(6, 14);
        let mut s: Vec<&str> = (0..n).map(|_| self.word(rng)).collect();
        // A few English function words, so that stop words are in play as in a real folder.
        s.insert(
            rng.below(n),
            ["the", "and", "of", "is", "with"][rng.below(5)],
        );
        let mut s = s.join(" ");
        if let Some(first) = s.get(..1) {
            s = first.to_uppercase() + &s[1..];
        }
        s + "."
    }

    fn paragraph(&self, rng: &mut Rng) -> String {
        let n = rng.between(3, 6);
        (0..n)
            .map(|_| self.sentence(rng))
            .collect::<Vec<_>>()
            .join(" ")
    }

    fn title(&self, rng: &mut Rng) -> String {
        let n = rng.between(1, 3);
        (0..n).map(|_| self.word(rng)).collect::<Vec<_>>().join(" ")
    }
}

/// Writes `files` Markdown files (ten subfolders) of a few sections each; returns the bytes written.
pub fn write_folder(
    dir: &Path,
    files: usize,
    rng: &mut Rng,
    vocabulary: &Vocabulary,
) -> anyhow::Result<u64> {
    let mut bytes = 0u64;
    for f in 0..files {
        let sub = dir.join(format!("part{}", f % 10));
        std::fs::create_dir_all(&sub)?;
        let mut text = format!(
            "# {}\n\n{}\n",
            vocabulary.title(rng),
            vocabulary.paragraph(rng)
        );
        for _ in 0..rng.between(1, 3) {
            text.push_str(&format!("\n## {}\n", vocabulary.title(rng)));
            for _ in 0..rng.between(1, 2) {
                text.push_str(&format!("\n{}\n", vocabulary.paragraph(rng)));
            }
        }
        bytes += text.len() as u64;
        std::fs::write(sub.join(format!("file{f:04}.md")), text)?;
    }
    Ok(bytes)
}

/// A question made from a passage: a question opening and 2 to 4 of its words.
pub fn question_from(text: &str, rng: &mut Rng) -> String {
    let words: Vec<&str> = text
        .split(|c: char| !c.is_alphanumeric())
        .filter(|w| w.len() > 3)
        .collect();
    let mut q = String::from(["what about", "tell me about", "where is", "how does"][rng.below(4)]);
    for _ in 0..rng.between(2, 4) {
        if words.is_empty() {
            break;
        }
        q.push(' ');
        q.push_str(&words[rng.below(words.len())].to_lowercase());
    }
    q.push('?');
    q
}

/// The baseline: every passage's text lowercased once, and per question the count of each of its words (longer
/// than two letters) as a substring of each passage; the three best.
pub struct NaiveScan {
    passages: Vec<String>,
}

impl NaiveScan {
    pub fn new(texts: impl IntoIterator<Item = String>) -> NaiveScan {
        NaiveScan {
            passages: texts.into_iter().map(|t| t.to_lowercase()).collect(),
        }
    }

    /// The ids of the three best passages, best first.
    pub fn top3(&self, question: &str) -> Vec<usize> {
        let question = question.to_lowercase();
        let words: Vec<&str> = question
            .split(|c: char| !c.is_alphanumeric())
            .filter(|w| w.len() > 2)
            .collect();
        let mut best: Vec<(usize, usize)> = Vec::with_capacity(4);
        for (id, text) in self.passages.iter().enumerate() {
            let count: usize = words.iter().map(|w| text.matches(w).count()).sum();
            if count == 0 {
                continue;
            }
            let at = best.partition_point(|(c, _)| *c >= count);
            if at < 3 {
                best.insert(at, (count, id));
                best.truncate(3);
            }
        }
        best.into_iter().map(|(_, id)| id).collect()
    }
}
