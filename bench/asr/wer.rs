//! The accuracy part of the ASR benchmark (`asr-bench`): word error rate over every speech fixture, per model and decoder,
//! through the satellite's path (the segmenter fed 20 ms messages, the fitted window, the filter) and on whole
//! clips, side by side in the same run with faster-whisper on the very same CTranslate2 weights at beam 1 and 5.

use std::path::{Path, PathBuf};
use std::time::Duration;

use whisper_sat::convert::{NoProgress, Weights, convert};
use whisper_sat::model_path::repo_root;
use whisper_sat::transcriber::{AudioContext, Outcome, Transcriber, TranscriberConfig};
use whisper_sat::wer::word_errors;

use crate::clips::{ClipAudio, clip_from, segment};
use crate::faster_whisper::{Baseline, FasterWhisper, faster_whisper};
use crate::fleet::Fleet;
use crate::jobs::write_jobs;

/// Peak RSS of one satellite process with `model` that has decoded every clip.
fn satellite_rss_mb(model: &Path, clips: &[ClipAudio]) -> anyhow::Result<f64> {
    let scratch = std::env::temp_dir().join(format!("whisper-sat-rss-{}", std::process::id()));
    std::fs::create_dir_all(&scratch)?;
    let jobs = scratch.join("clips.f32");
    let result = (|| {
        write_jobs(
            &jobs,
            &clips.iter().map(|c| c.audio.clone()).collect::<Vec<_>>(),
        )?;
        let mut fleet = Fleet::start(1, model, &jobs, &scratch.join("cores"))?;
        fleet.throughput(clips.len())?;
        Ok(fleet.peak_rss_mb().first().copied().unwrap_or(f64::NAN))
    })();
    let _ = std::fs::remove_dir_all(&scratch);
    result
}

/// A model under test: its ggml file and the CTranslate2 directory it was converted from.
pub struct ModelUnderTest {
    pub name: &'static str,
    pub ggml: PathBuf,
    pub ct2: PathBuf,
    /// It hears languages other than English.
    pub multilingual: bool,
}

/// Speech to score: clips with their reference transcripts, in one language.
pub struct Suite {
    pub name: &'static str,
    /// The Whisper language code both decoders are given.
    pub language: &'static str,
    pub clips: Vec<ClipAudio>,
    pub references: Vec<String>,
}

impl Suite {
    /// Every suite there is speech for: the fixture clips (read again from their files), then LibriVox and the
    /// Italian prompts when their packages are installed.
    pub fn all(clips: &[ClipAudio]) -> anyhow::Result<Vec<Suite>> {
        let mut suites = vec![Suite::fixtures(
            clips
                .iter()
                .map(|c| clip_from(&c.name, &c.path))
                .collect::<anyhow::Result<_>>()?,
        )?];
        suites.extend(Suite::librivox()?);
        suites.extend(Suite::italian_prompts()?);
        Ok(suites)
    }

    /// The fixture clips, with the `.txt` transcript beside each.
    pub fn fixtures(clips: Vec<ClipAudio>) -> anyhow::Result<Suite> {
        let references = clips
            .iter()
            .map(|c| {
                let txt = c.path.with_extension("txt");
                std::fs::read_to_string(&txt)
                    .map(|s| s.trim().to_owned())
                    .map_err(|e| anyhow::anyhow!("{}: {e}", txt.display()))
            })
            .collect::<anyhow::Result<_>>()?;
        Ok(Suite {
            name: "English fixtures",
            language: "en",
            clips,
            references,
        })
    }

    /// Real Italian speech: Asterisk's Italian prompts, read by Carlo Flora (Debian's
    /// `asterisk-core-sounds-it-wav`, CC-BY-3.0; 8 kHz telephone audio), with the transcripts the package ships.
    /// `None` when the package is not installed.
    pub fn italian_prompts() -> anyhow::Result<Option<Suite>> {
        let dir = Path::new("/usr/share/asterisk/sounds/it_IT_m_Carlo");
        let list = "/usr/share/doc/asterisk-core-sounds-it/core-sounds-it.txt.gz";
        if !dir.is_dir() || !Path::new(list).is_file() {
            return Ok(None);
        }
        let text = std::process::Command::new("zcat").arg(list).output()?;
        let text = String::from_utf8_lossy(&text.stdout);
        let mut clips = Vec::new();
        let mut references = Vec::new();
        for name in ITALIAN_PROMPTS {
            let reference = text
                .lines()
                .find_map(|l| l.strip_prefix(&format!("{name}: ")))
                .ok_or_else(|| anyhow::anyhow!("no transcript of {name} in {list}"))?;
            clips.push(clip_from(name, &dir.join(format!("{name}.wav")))?);
            references.push(reference.trim().to_owned());
        }
        Ok(Some(Suite {
            name: "Italian prompts",
            language: "it",
            clips,
            references,
        }))
    }

    /// Real English read speech beyond the fixtures: five LibriVox utterances of "Sense and Sensibility" (public
    /// domain) that Debian's `pocketsphinx-testdata` ships with their transcription. Its spelling is the
    /// recognisers' own ("mister" for "Mr.", the reader's slip "a more a amiable" kept), which costs every decoder
    /// alike. `None` when the package is not installed.
    pub fn librivox() -> anyhow::Result<Option<Suite>> {
        let dir = Path::new("/usr/share/pocketsphinx/test/data/librivox");
        let Ok(text) = std::fs::read_to_string(dir.join("transcription")) else {
            return Ok(None);
        };
        let mut clips = Vec::new();
        let mut references = Vec::new();
        // Lines read `<s> words </s> (file id)`.
        for line in text.lines().filter(|l| !l.trim().is_empty()) {
            let (words, id) = line
                .rsplit_once(" (")
                .ok_or_else(|| anyhow::anyhow!("unexpected transcription line {line:?}"))?;
            let id = id.trim_end_matches(')');
            let words = words.replace("<s>", "").replace("</s>", "");
            clips.push(clip_from(id, &dir.join(format!("{id}.wav")))?);
            references.push(words.trim().to_owned());
        }
        Ok(Some(Suite {
            name: "LibriVox",
            language: "en",
            clips,
            references,
        }))
    }
}

/// Prompts whose transcript is exactly what is said: those spelling numbers as digits, or with the package's
/// misspellings ("Perpiacere"), are left out.
const ITALIAN_PROMPTS: [&str; 18] = [
    "all-circuits-busy-now",
    "conf-extended",
    "conf-getconfno",
    "conf-getpin",
    "conf-invalid",
    "conf-leaderhasleft",
    "conf-locked",
    "conf-noempty",
    "conf-onlyperson",
    "from-unknown-caller",
    "queue-periodic-announce",
    "ss-noservice",
    "vm-mailboxfull",
    "vm-newpassword",
    "vm-newuser",
    "vm-nomore",
    "privacy-unident",
    "vm-enter-num-to-call",
];

/// tiny.en, and base when `make model MODEL=base` has provisioned it.
pub fn provisioned_models(tiny: &Path, tiny_ct2: &Path) -> Vec<ModelUnderTest> {
    let mut models = vec![ModelUnderTest {
        name: "tiny.en",
        ggml: tiny.to_path_buf(),
        ct2: tiny_ct2.to_path_buf(),
        multilingual: false,
    }];
    let base = ModelUnderTest {
        name: "base",
        ggml: repo_root().join("models/ggml-base.bin"),
        ct2: repo_root().join("models/cache/whisper-base-ct2"),
        multilingual: true,
    };
    if base.ggml.is_file() && base.ct2.join("model.bin").is_file() {
        models.push(base);
    }
    models
}

/// One decoder's result over every clip.
struct Row {
    decoder: String,
    errors: usize,
    words: usize,
    /// Inference seconds per audio second.
    rtf: f64,
    /// End of speech to transcript (speculative), utterances of at most 5 s: median and p95, satellite path only.
    latency: Option<(Duration, Duration)>,
}

impl Row {
    fn wer(&self) -> f64 {
        self.errors as f64 / self.words.max(1) as f64
    }
}

/// Word errors and inference time summed over clips.
#[derive(Default)]
struct Tally {
    errors: usize,
    words: usize,
    processing: f64,
    audio: f64,
}

impl Tally {
    fn add(&mut self, reference: &str, hypothesis: &str, processing: f64, audio: f64) {
        let (e, n) = word_errors(reference, hypothesis);
        self.errors += e;
        self.words += n;
        self.processing += processing;
        self.audio += audio;
    }

    fn row(&self, decoder: String, latency: Option<(Duration, Duration)>) -> Row {
        Row {
            decoder,
            errors: self.errors,
            words: self.words,
            rtf: self.processing / self.audio,
            latency,
        }
    }
}

fn percentile(v: &[Duration], p: f64) -> Duration {
    let mut s = v.to_vec();
    s.sort();
    s.get(((s.len().saturating_sub(1)) as f64 * p).round() as usize)
        .copied()
        .unwrap_or_default()
}

/// Our decoder through the satellite's path: the clip segmented as the hub delivers it, each utterance decoded
/// and filtered, the accepted texts joined.
fn satellite_path(
    t: &mut Transcriber,
    clips: &[ClipAudio],
    references: &[String],
) -> anyhow::Result<Row> {
    let mut tally = Tally::default();
    let mut latencies = Vec::new();
    for (c, reference) in clips.iter().zip(references) {
        let mut texts = Vec::new();
        let mut processing = 0.0;
        for s in segment(&c.audio)? {
            let outcome = t.transcribe(&s.audio)?;
            let d = match &outcome {
                Outcome::Speech(d) => {
                    texts.push(d.text.clone());
                    d
                }
                Outcome::Rejected(_, d) => d,
            };
            processing += d.processing.as_secs_f64();
            if s.audio.len() <= 5 * 16_000 {
                latencies.push(s.latency(d.processing).0);
            }
        }
        tally.add(reference, &texts.join(" "), processing, c.seconds());
    }
    Ok(tally.row(
        String::new(),
        Some((percentile(&latencies, 0.5), percentile(&latencies, 0.95))),
    ))
}

/// Our decoder on each clip whole, as faster-whisper is run.
fn whole_clips(
    t: &mut Transcriber,
    clips: &[ClipAudio],
    references: &[String],
) -> anyhow::Result<Row> {
    let mut tally = Tally::default();
    for (c, reference) in clips.iter().zip(references) {
        let d = t.decode(&c.audio)?;
        tally.add(reference, &d.text, d.processing.as_secs_f64(), c.seconds());
    }
    Ok(tally.row(String::new(), None))
}

fn baseline_row(b: &Baseline, clips: &[ClipAudio], references: &[String]) -> Row {
    let mut tally = Tally::default();
    for ((text, reference), (c, seconds)) in b
        .texts
        .iter()
        .zip(references)
        .zip(clips.iter().zip(&b.per_clip))
    {
        tally.add(reference, text, *seconds, c.seconds());
    }
    tally.row(
        format!(
            "faster-whisper {} beam {} (whole clips)",
            b.compute_type, b.beam
        ),
        None,
    )
}

/// Runs every model and decoder on every suite it can hear; returns the Markdown table rows and the SUMMARY
/// lines. Each model's memory is measured once, on the first suite.
pub fn wer_bench(
    models: &[ModelUnderTest],
    python: &Path,
    threads: usize,
    suites: &[Suite],
) -> anyhow::Result<(Vec<String>, Vec<String>)> {
    let mut table = vec![
        "| speech | model | decoder | WER | errors / words | RTF | end of speech -> transcript, <= 5 s, median / p95 ms |".to_owned(),
        "|---|---|---|---|---|---|---|".to_owned(),
    ];
    let mut summary = Vec::new();
    for m in models {
        // The same weights in 8 bits (`--weights q8_0`), converted here from the same CTranslate2 directory.
        let q8 = std::env::temp_dir().join(format!(
            "whisper-sat-bench-{}-q8_0-{}.bin",
            m.name,
            std::process::id()
        ));
        convert(&m.ct2, &q8, Weights::Q8_0, &mut NoProgress)?;
        let result = (|| {
            for (i, suite) in suites.iter().enumerate() {
                if suite.language != "en" && !m.multilingual {
                    continue;
                }
                let rows = score(m, &q8, suite, python, threads)?;
                report(m, suite, &rows, &mut table, &mut summary)?;
                if i == 0 {
                    let mb =
                        |p: &Path| std::fs::metadata(p).map_or(f64::NAN, |f| f.len() as f64 / 1e6);
                    let rss = satellite_rss_mb(&m.ggml, &suite.clips)?;
                    let rss_q8 = satellite_rss_mb(&q8, &suite.clips)?;
                    summary.push(format!(
                        "SUMMARY asr model {}: peak rss of a satellite {rss:.0} MB (model file {:.0} MB); with q8_0 \
                         weights {rss_q8:.0} MB (model file {:.0} MB, ratio {:.2})",
                        m.name,
                        mb(&m.ggml),
                        mb(&q8),
                        rss_q8 / rss,
                    ));
                }
            }
            anyhow::Ok(())
        })();
        let _ = std::fs::remove_file(&q8);
        result?;
    }
    Ok((table, summary))
}

/// The floor `--unsure-retry` is benched at: measured per clip (docs/asr.md), the fitted decodes below it were the
/// ones the full window corrects.
const UNSURE_LOGPROB: f32 = -0.3;

/// Our decoders at beam 1 and 5 (satellite path and whole clips), the default decoder on the model's `q8_0`
/// conversion, and faster-whisper's on one suite.
fn score(
    m: &ModelUnderTest,
    q8: &Path,
    suite: &Suite,
    python: &Path,
    threads: usize,
) -> anyhow::Result<Vec<Row>> {
    let (clips, references) = (&suite.clips, &suite.references);
    let mut rows = Vec::new();
    // The default, beam search, the full 30 s encoder window instead of the fitted one (`--full-window`), and the
    // full window only for unsure decodes (`--unsure-retry`): the choices that trade latency for accuracy.
    for (model, beam, window, unsure, label) in [
        (m.ggml.as_path(), 1, AudioContext::Fit, None, ""),
        (m.ggml.as_path(), 5, AudioContext::Fit, None, ""),
        (
            m.ggml.as_path(),
            1,
            AudioContext::Full,
            None,
            " full window",
        ),
        (
            m.ggml.as_path(),
            1,
            AudioContext::Fit,
            Some(UNSURE_LOGPROB),
            " unsure retried",
        ),
        (q8, 1, AudioContext::Fit, None, " q8_0 weights"),
    ] {
        let mut t = Transcriber::load(
            model,
            TranscriberConfig {
                threads,
                beam_size: beam,
                audio_context: window,
                unsure_logprob: unsure,
                language: suite.language.to_owned(),
                ..TranscriberConfig::default()
            },
        )?;
        // A warm-up decode, so the first clip does not pay for the allocations.
        t.decode(&clips[0].audio)?;
        let mut row = satellite_path(&mut t, clips, references)?;
        row.decoder = format!("whisper-sat beam {beam}{label} (satellite path)");
        rows.push(row);
        let mut row = whole_clips(&mut t, clips, references)?;
        row.decoder = format!("whisper-sat beam {beam}{label} (whole clips)");
        rows.push(row);
    }
    let fw = FasterWhisper {
        python,
        ct2: &m.ct2,
        language: suite.language,
        compute_types: &["int8"],
        beams: &[1, 5],
    };
    let (baselines, _) = faster_whisper(&fw, threads, 1, clips)?;
    rows.extend(baselines.iter().map(|b| baseline_row(b, clips, references)));
    Ok(rows)
}

fn report(
    m: &ModelUnderTest,
    suite: &Suite,
    rows: &[Row],
    table: &mut Vec<String>,
    summary: &mut Vec<String>,
) -> anyhow::Result<()> {
    for r in rows {
        table.push(format!(
            "| {} | {} | {} | {:.1}% | {} / {} | {:.3} | {} |",
            suite.name,
            m.name,
            r.decoder,
            r.wer() * 100.0,
            r.errors,
            r.words,
            r.rtf,
            r.latency.map_or("-".to_owned(), |(p50, p95)| format!(
                "{:.0} / {:.0}",
                p50.as_secs_f64() * 1000.0,
                p95.as_secs_f64() * 1000.0
            ))
        ));
    }
    let find = |name: &str| rows.iter().find(|r| r.decoder == name);
    let (Some(ours), Some(ours5), Some(full), Some(unsure), Some(q8), Some(fw5)) = (
        find("whisper-sat beam 1 (satellite path)"),
        find("whisper-sat beam 5 (satellite path)"),
        find("whisper-sat beam 1 full window (satellite path)"),
        find("whisper-sat beam 1 unsure retried (satellite path)"),
        find("whisper-sat beam 1 q8_0 weights (satellite path)"),
        find("faster-whisper int8 beam 5 (whole clips)"),
    ) else {
        anyhow::bail!("a decoder of {} did not run", m.name);
    };
    let ratio = |a: &Row| {
        if fw5.errors == 0 {
            // No errors to compare against: equal when ours has none either.
            if a.errors == 0 { 1.0 } else { f64::INFINITY }
        } else {
            a.wer() / fw5.wer()
        }
    };
    let ms = |d: Duration| d.as_secs_f64() * 1000.0;
    for (label, r) in [
        ("beam 1, the default", ours),
        ("beam 5", ours5),
        ("beam 1, full window", full),
        ("beam 1, unsure retried at -0.3", unsure),
    ] {
        let (p50, p95) = r.latency.unwrap_or_default();
        summary.push(format!(
            "SUMMARY asr wer {} on {} ({label}, satellite path): {:.1}% ({}/{} words; baseline faster-whisper int8 beam 5 {:.1}%, ratio {:.2}); RTF {:.3} (faster-whisper beam 5 {:.3}, ratio {:.2}); end of speech -> transcript p50 {:.0} ms, p95 {:.0} ms (target 500 ms)",
            m.name,
            suite.name,
            r.wer() * 100.0,
            r.errors,
            r.words,
            fw5.wer() * 100.0,
            ratio(r),
            r.rtf,
            fw5.rtf,
            r.rtf / fw5.rtf,
            ms(p50),
            ms(p95),
        ));
    }
    summary.push(format!(
        "SUMMARY asr weights q8_0 {} on {} (beam 1, satellite path): WER {:.1}% ({}/{} words; f16 weights {:.1}% ({}/{}); \
         faster-whisper int8 beam 5 {:.1}%, ratio {:.2}); RTF {:.3} (f16 weights {:.3}, ratio {:.2})",
        m.name,
        suite.name,
        q8.wer() * 100.0,
        q8.errors,
        q8.words,
        ours.wer() * 100.0,
        ours.errors,
        ours.words,
        fw5.wer() * 100.0,
        ratio(q8),
        q8.rtf,
        ours.rtf,
        q8.rtf / ours.rtf,
    ));
    Ok(())
}
