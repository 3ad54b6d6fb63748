//! Trying a knowledge folder without the agent: what it indexed, and what each question finds.
//!
//! ```text
//! cargo run --example ask -- knowledge/                 # then type questions, one a line
//! cargo run --example ask -- knowledge/ --it            # Italian stemming and stop words
//! cargo run --example ask -- knowledge/ --list          # every passage as it would be spoken
//! ```

use std::io::BufRead;

use agent_knowledge::{Knowledge, Language, MIN_COVERAGE};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = args
        .iter()
        .find(|a| !a.starts_with("--"))
        .map_or("knowledge/", String::as_str);
    let language = if args.iter().any(|a| a == "--it") {
        Language::It
    } else {
        Language::En
    };
    let knowledge = Knowledge::open(dir, language)?;
    println!(
        "{dir}: {} files, {} passages, {} skipped",
        knowledge.files(),
        knowledge.passages(),
        knowledge.skipped().len()
    );
    for skipped in knowledge.skipped() {
        println!("  skipped {}: {:?}", skipped.path, skipped.reason);
    }
    if args.iter().any(|a| a == "--list") {
        for hit in knowledge.all() {
            println!("{} [{}]\n  {}", hit.file, hit.heading, hit.text);
        }
        return Ok(());
    }
    for line in std::io::stdin().lock().lines() {
        let question = line?;
        if question.trim().is_empty() {
            continue;
        }
        match knowledge.candidate(&question) {
            Some(c) if c.coverage >= MIN_COVERAGE && c.matched >= agent_knowledge::MIN_MATCHED => {
                println!(
                    "best: {} [{}] (coverage {:.2})\n  {}",
                    c.hit.file, c.hit.heading, c.coverage, c.hit.text
                )
            }
            Some(c) => println!(
                "best: none (closest {} [{}], coverage {:.2} of at least {MIN_COVERAGE}, {} terms shared of at least {})",
                c.hit.file,
                c.hit.heading,
                c.coverage,
                c.matched,
                agent_knowledge::MIN_MATCHED
            ),
            None => println!("best: none (no passage shares a word with the question)"),
        }
        for hit in knowledge.search(&question, 3) {
            println!("  {:6.2} {} [{}]", hit.score, hit.file, hit.heading);
        }
    }
    Ok(())
}
