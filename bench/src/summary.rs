//! The SUMMARY blocks of docs/benchmarks.md: the lines a bench prints, picked out of its saved output, and the
//! block between `<!-- summary:NAME -->` and `<!-- /summary:NAME -->` rewritten with them and when they were taken,
//! so that no figure there is copied by hand.

use agent_brain::WallClock;

/// Why a document's blocks cannot be read or rewritten.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SummaryError {
    #[error("block `{0}` is opened and never closed")]
    Unclosed(String),
    #[error("block `{0}` is closed and was not open")]
    Unopened(String),
    #[error("block `{0}` is opened inside block `{1}`")]
    Nested(String, String),
    #[error("block `{0}` appears twice")]
    Duplicate(String),
    #[error("no block `{0}` in the document")]
    Missing(String),
}

/// Whether a line of a bench's output belongs in its block: its `SUMMARY` figures and the `TARGET` verdicts that
/// some benches print beside them.
pub fn is_summary_line(line: &str) -> bool {
    line.starts_with("SUMMARY ") || line.starts_with("TARGET ")
}

/// The summary lines of a bench's output, in the order printed, without trailing blanks.
pub fn summary_lines(log: &str) -> Vec<&str> {
    log.lines()
        .map(str::trim_end)
        .filter(|l| is_summary_line(l))
        .collect()
}

/// When and from what a block's lines were taken.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Taken {
    /// The day of the run, `YYYY-MM-DD`.
    pub date: String,
    /// The commit the bench ran at (`git describe --always --dirty`).
    pub commit: String,
}

/// A block's new content: the stamp, then the lines in a code fence.
pub fn render(lines: &[&str], taken: &Taken) -> String {
    let mut out = format!(
        "Taken on {} at commit `{}`; copied from the run's output by `bench-summary`.\n\n```\n",
        taken.date, taken.commit
    );
    for line in lines {
        out.push_str(line);
        out.push('\n');
    }
    out.push_str("```\n");
    out
}

/// A marker line: `Some((true, name))` opens block `name`, `Some((false, name))` closes it.
fn marker(line: &str) -> Option<(bool, &str)> {
    let inner = line
        .trim()
        .strip_prefix("<!--")?
        .strip_suffix("-->")?
        .trim();
    if let Some(name) = inner.strip_prefix("/summary:") {
        Some((false, name.trim()))
    } else {
        inner
            .strip_prefix("summary:")
            .map(|name| (true, name.trim()))
    }
}

/// Each block of `doc` as its name and the indices of its opening and closing lines (in `split_inclusive` lines),
/// in document order; an error if the markers do not pair up.
fn blocks(doc: &str) -> Result<Vec<(String, usize, usize)>, SummaryError> {
    let mut out: Vec<(String, usize, usize)> = Vec::new();
    let mut open: Option<(&str, usize)> = None;
    for (i, line) in doc.split_inclusive('\n').enumerate() {
        match (marker(line), open) {
            (None, _) => {}
            (Some((true, name)), None) => {
                if out.iter().any(|(n, _, _)| n == name) {
                    return Err(SummaryError::Duplicate(name.to_owned()));
                }
                open = Some((name, i));
            }
            (Some((true, name)), Some((outer, _))) => {
                return Err(SummaryError::Nested(name.to_owned(), outer.to_owned()));
            }
            (Some((false, name)), Some((opened, start))) if name == opened => {
                out.push((name.to_owned(), start, i));
                open = None;
            }
            (Some((false, name)), _) => return Err(SummaryError::Unopened(name.to_owned())),
        }
    }
    match open {
        Some((name, _)) => Err(SummaryError::Unclosed(name.to_owned())),
        None => Ok(out),
    }
}

/// The names of the blocks in `doc`, in document order.
pub fn block_names(doc: &str) -> Result<Vec<String>, SummaryError> {
    Ok(blocks(doc)?.into_iter().map(|(name, _, _)| name).collect())
}

/// `doc` with everything between the markers of block `name` replaced by `body` (the markers and the rest of the
/// document as they were).
pub fn replace_block(doc: &str, name: &str, body: &str) -> Result<String, SummaryError> {
    let (_, start, end) = blocks(doc)?
        .into_iter()
        .find(|(n, _, _)| n == name)
        .ok_or_else(|| SummaryError::Missing(name.to_owned()))?;
    let lines: Vec<&str> = doc.split_inclusive('\n').collect();
    let mut out: String = lines[..=start].concat();
    out.push_str(body);
    if !body.is_empty() && !body.ends_with('\n') {
        out.push('\n');
    }
    out.push_str(&lines[end..].concat());
    Ok(out)
}

/// The UTC day of a Unix time, `YYYY-MM-DD`, from the brain's calendar (`agent_brain::WallClock`).
pub fn utc_date(unix_secs: u64) -> String {
    // Seconds since 1970 fit i64 for the next 292 billion years; past that the date saturates.
    let ms = i64::try_from(unix_secs).unwrap_or(i64::MAX / 1000) * 1000;
    let day = WallClock::from_unix_ms(ms, 0);
    format!("{:04}-{:02}-{:02}", day.year, day.month, day.day)
}

/// What `git describe --always --dirty` says, or "unknown" outside a work tree: a stamp is no reason to fail.
pub fn current_commit() -> String {
    std::process::Command::new("git")
        .args(["describe", "--always", "--dirty"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_owned())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "unknown".to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    const DOC: &str = "# Benchmarks\n\nIntro.\n\n<!-- summary:hub-bench -->\n```\nSUMMARY old\n```\n\
                       <!-- /summary:hub-bench -->\n\nProse.\n<!-- summary:voice-bench -->\n<!-- /summary:voice-bench -->\nEnd.\n";

    fn taken() -> Taken {
        Taken {
            date: "2025-01-02".into(),
            commit: "abc1234".into(),
        }
    }

    #[test]
    fn summary_and_target_lines_are_picked_in_order_and_the_rest_dropped() {
        let log = "starting\nSUMMARY a: 1 ms  \nhub-bench: rounds [1, 2]\nTARGET x: PASS\n  SUMMARY indented\nSUMMARYX\n";
        assert_eq!(summary_lines(log), ["SUMMARY a: 1 ms", "TARGET x: PASS"]);
    }

    #[test]
    fn render_stamps_the_date_and_commit_above_a_fence_of_the_lines() {
        assert_eq!(
            render(&["SUMMARY a", "SUMMARY b"], &taken()),
            "Taken on 2025-01-02 at commit `abc1234`; copied from the run's output by `bench-summary`.\n\n\
             ```\nSUMMARY a\nSUMMARY b\n```\n"
        );
    }

    #[test]
    fn block_names_come_in_document_order() {
        assert_eq!(
            block_names(DOC),
            Ok(vec!["hub-bench".to_owned(), "voice-bench".to_owned()])
        );
    }

    #[test]
    fn replacing_a_block_changes_only_what_is_between_its_markers() {
        let body = render(&["SUMMARY new"], &taken());
        let out = replace_block(DOC, "hub-bench", &body).expect("block");
        assert!(out.starts_with(
            "# Benchmarks\n\nIntro.\n\n<!-- summary:hub-bench -->\nTaken on 2025-01-02"
        ));
        assert!(out.contains("```\nSUMMARY new\n```\n<!-- /summary:hub-bench -->\n\nProse.\n"));
        assert!(!out.contains("SUMMARY old"));
        assert!(
            out.ends_with("<!-- summary:voice-bench -->\n<!-- /summary:voice-bench -->\nEnd.\n")
        );
    }

    #[test]
    fn an_empty_block_is_filled_and_rewriting_twice_gives_the_same_document() {
        let body = render(&["SUMMARY v"], &taken());
        let once = replace_block(DOC, "voice-bench", &body).expect("block");
        assert!(once.ends_with("<!-- summary:voice-bench -->\nTaken on 2025-01-02 at commit `abc1234`; copied from the run's output by `bench-summary`.\n\n```\nSUMMARY v\n```\n<!-- /summary:voice-bench -->\nEnd.\n"));
        assert_eq!(replace_block(&once, "voice-bench", &body), Ok(once.clone()));
    }

    #[test]
    fn a_body_without_a_final_newline_still_leaves_the_closing_marker_on_its_own_line() {
        let out = replace_block(DOC, "voice-bench", "x").expect("block");
        assert!(out.contains("<!-- summary:voice-bench -->\nx\n<!-- /summary:voice-bench -->\n"));
    }

    #[test]
    fn markers_that_do_not_pair_up_are_errors() {
        let unclosed = "<!-- summary:a -->\ntext\n";
        assert_eq!(
            block_names(unclosed),
            Err(SummaryError::Unclosed("a".into()))
        );
        let unopened = "text\n<!-- /summary:a -->\n";
        assert_eq!(
            block_names(unopened),
            Err(SummaryError::Unopened("a".into()))
        );
        let crossed = "<!-- summary:a -->\n<!-- /summary:b -->\n";
        assert_eq!(
            block_names(crossed),
            Err(SummaryError::Unopened("b".into()))
        );
        let nested =
            "<!-- summary:a -->\n<!-- summary:b -->\n<!-- /summary:b -->\n<!-- /summary:a -->\n";
        assert_eq!(
            block_names(nested),
            Err(SummaryError::Nested("b".into(), "a".into()))
        );
        let twice =
            "<!-- summary:a -->\n<!-- /summary:a -->\n<!-- summary:a -->\n<!-- /summary:a -->\n";
        assert_eq!(block_names(twice), Err(SummaryError::Duplicate("a".into())));
    }

    #[test]
    fn a_block_that_is_not_there_is_an_error() {
        assert_eq!(
            replace_block(DOC, "asr-bench", "x\n"),
            Err(SummaryError::Missing("asr-bench".into()))
        );
    }

    #[test]
    fn other_html_comments_are_not_markers() {
        assert_eq!(
            block_names("<!-- a note -->\n<!-- summary -->\n"),
            Ok(vec![])
        );
    }

    #[test]
    fn utc_dates_cross_month_year_and_leap_day_boundaries() {
        assert_eq!(utc_date(0), "1970-01-01");
        assert_eq!(utc_date(86_399), "1970-01-01");
        assert_eq!(utc_date(31 * 86_400), "1970-02-01");
        // 2000 is a leap year (divisible by 400); 2100, a century not divisible by 400, is not.
        assert_eq!(utc_date(951_782_400), "2000-02-29");
        assert_eq!(utc_date(951_868_800), "2000-03-01");
        assert_eq!(utc_date(1_709_164_800), "2024-02-29");
        assert_eq!(utc_date(1_735_689_599), "2024-12-31");
        assert_eq!(utc_date(1_735_689_600), "2025-01-01");
        assert_eq!(utc_date(4_107_456_000), "2100-02-28");
        assert_eq!(utc_date(4_107_542_400), "2100-03-01");
    }
}
