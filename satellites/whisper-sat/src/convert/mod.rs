//! Conversion of a CTranslate2 Whisper model directory (`model.bin`, `vocabulary.txt`) to a ggml file for
//! whisper.cpp: tensor names mapped, fused attention projections split, mel filters and raw-byte vocabulary added.

pub mod ct2;
pub mod ggml;
pub mod mel;
pub mod vocabulary;

use std::fs::File;
use std::io::{BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};

use ct2::{Ct2Error, Ct2Model, Variable};
pub use ggml::Weights;
use ggml::{Hparams, TensorType};
use vocabulary::VocabularyError;

/// Whisper's front end: 16 kHz audio, 400-point FFT.
const SAMPLE_RATE: f64 = 16_000.0;
const N_FFT: usize = 400;

/// Errors from converting a model.
#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {source}")]
    Model { path: PathBuf, source: Ct2Error },
    #[error("{path}: {source}")]
    Vocabulary {
        path: PathBuf,
        source: VocabularyError,
    },
    #[error("{path}: spec {spec:?} is not a Whisper model (expected WhisperSpec)")]
    NotWhisper { path: PathBuf, spec: String },
    #[error("unexpected model layout: {0}")]
    Layout(String),
}

/// What a conversion produced, for the caller to report.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConvertSummary {
    pub hparams: Hparams,
    pub tensors: usize,
    pub vocabulary: usize,
    pub bytes: u64,
}

/// Progress callbacks, so the library stays free of terminal concerns: `phase` names the step, `total` its size in
/// bytes and `advance` the bytes done so far in it.
pub trait Progress {
    fn phase(&mut self, name: &str, total: u64);
    fn advance(&mut self, done: u64);
}

/// A progress sink that ignores everything (tests, library callers).
#[derive(Debug, Default)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn phase(&mut self, _: &str, _: u64) {}
    fn advance(&mut self, _: u64) {}
}

/// One output tensor: a slice of rows of a CT2 variable, stored under a ggml name.
#[derive(Debug)]
struct Planned<'m> {
    name: String,
    source: &'m Variable,
    /// Element range within the source (row slices of fused projections); the whole variable when `None`.
    range: Option<(usize, usize)>,
    shape: Vec<usize>,
    ttype: TensorType,
}

/// Converts `ct2_dir` into the ggml file `out`, its weight matrices stored as `weights` says. The file is written
/// beside `out` under a temporary name and renamed at the end, so an interrupted conversion never leaves a
/// truncated model behind.
pub fn convert(
    ct2_dir: &Path,
    out: &Path,
    weights: Weights,
    progress: &mut dyn Progress,
) -> Result<ConvertSummary, ConvertError> {
    let model_path = ct2_dir.join("model.bin");
    let io_err = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ConvertError::Io { path, source }
    };
    let file = File::open(&model_path).map_err(io_err(&model_path))?;
    let size = file.metadata().map_err(io_err(&model_path))?.len();
    progress.phase("reading model.bin", size);
    let model =
        Ct2Model::read(BufReader::new(file), |n| progress.advance(n)).map_err(|source| {
            ConvertError::Model {
                path: model_path.clone(),
                source,
            }
        })?;
    if model.spec != "WhisperSpec" {
        return Err(ConvertError::NotWhisper {
            path: model_path,
            spec: model.spec,
        });
    }
    let vocab_path = ct2_dir.join("vocabulary.txt");
    let vocab_text = std::fs::read_to_string(&vocab_path).map_err(io_err(&vocab_path))?;
    let vocabulary =
        vocabulary::decode_vocabulary(&vocab_text).map_err(|source| ConvertError::Vocabulary {
            path: vocab_path,
            source,
        })?;

    let hparams = hparams(&model, weights)?;
    let plan = plan_tensors(&model, &hparams, weights)?;
    let mel = mel::slaney_filterbank(SAMPLE_RATE, N_FFT, hparams.n_mels as usize);

    let tmp = out.with_extension("bin.partial");
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
    }
    let file = File::create(&tmp).map_err(io_err(&tmp))?;
    let mut w = BufWriter::new(file);
    let total: u64 = plan
        .iter()
        .map(|p| p.ttype.bytes(p.shape.iter().product::<usize>()) as u64)
        .sum();
    progress.phase("writing ggml tensors", total);
    ggml::write_header(&mut w, &hparams, N_FFT / 2 + 1, &mel, &vocabulary).map_err(io_err(&tmp))?;
    let mut written = 0u64;
    let mut data_done = 0u64;
    for p in &plan {
        let values = p.source.to_f32();
        let values = match p.range {
            Some((a, b)) => &values[a..b],
            None => &values[..],
        };
        written +=
            ggml::write_tensor(&mut w, &p.name, &p.shape, p.ttype, values).map_err(io_err(&tmp))?;
        data_done += p.ttype.bytes(values.len()) as u64;
        progress.advance(data_done);
    }
    w.flush().map_err(io_err(&tmp))?;
    w.into_inner()
        .map_err(|e| ConvertError::Io {
            path: tmp.clone(),
            source: e.into_error(),
        })?
        .sync_all()
        .map_err(io_err(&tmp))?;
    std::fs::rename(&tmp, out).map_err(io_err(out))?;
    Ok(ConvertSummary {
        hparams,
        tensors: plan.len(),
        vocabulary: vocabulary.len(),
        bytes: written,
    })
}

/// Number of layers under `prefix` ("encoder" or "decoder"), counted by the `layer_<digits>/` pattern so that
/// `encoder/layer_norm/...` is not mistaken for a layer.
fn count_layers(model: &Ct2Model, prefix: &str) -> usize {
    let lead = format!("{prefix}/layer_");
    model
        .variables
        .iter()
        .filter_map(|v| v.name.strip_prefix(&lead))
        .filter_map(|rest| {
            let (digits, _) = rest.split_once('/')?;
            (!digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()))
                .then(|| digits.parse::<usize>().ok())
                .flatten()
        })
        .max()
        .map_or(0, |m| m + 1)
}

fn layout(msg: impl Into<String>) -> ConvertError {
    ConvertError::Layout(msg.into())
}

fn get<'m>(model: &'m Ct2Model, name: &str) -> Result<&'m Variable, ConvertError> {
    model.get(name).map_err(|e| layout(e.to_string()))
}

fn dim(v: &Variable, i: usize) -> Result<i32, ConvertError> {
    v.dims
        .get(i)
        .map(|&d| d as i32)
        .ok_or_else(|| layout(format!("{} has shape {:?}", v.name, v.dims)))
}

fn hparams(model: &Ct2Model, weights: Weights) -> Result<Hparams, ConvertError> {
    let enc_pos = get(model, "encoder/position_encodings/encodings")?;
    let dec_pos = get(model, "decoder/position_encodings/encodings")?;
    let emb = get(model, "decoder/embeddings/weight")?;
    let conv1 = get(model, "encoder/conv1/weight")?;
    let heads = |name: &str| -> Result<i32, ConvertError> {
        let v = get(model, name)?;
        v.scalar_i64()
            .map(|h| h as i32)
            .map_err(|e| layout(e.to_string()))
    };
    Ok(Hparams {
        n_vocab: dim(emb, 0)?,
        n_audio_ctx: dim(enc_pos, 0)?,
        n_audio_state: dim(enc_pos, 1)?,
        n_audio_head: heads("encoder/num_heads")?,
        n_audio_layer: count_layers(model, "encoder") as i32,
        n_text_ctx: dim(dec_pos, 0)?,
        n_text_state: dim(dec_pos, 1)?,
        n_text_head: heads("decoder/num_heads")?,
        n_text_layer: count_layers(model, "decoder") as i32,
        n_mels: dim(conv1, 1)?,
        ftype: weights.ftype(),
    })
}

/// Collects the output tensors in file order.
struct Planner<'m> {
    model: &'m Ct2Model,
    weights: Weights,
    plan: Vec<Planned<'m>>,
}

impl<'m> Planner<'m> {
    /// Matrices as `weights` says, except the convolutions (three dimensions), which whisper.cpp keeps in f16
    /// even in quantised models; vectors, the conv biases and the positional embeddings f32. That is what
    /// whisper.cpp allocates for them.
    fn add(
        &mut self,
        name: String,
        source: &'m Variable,
        range: Option<(usize, usize)>,
        shape: Vec<usize>,
    ) {
        let conv_bias = name.starts_with("encoder.conv") && name.ends_with(".bias");
        let ttype = if shape.len() < 2 || conv_bias || name.ends_with("positional_embedding") {
            TensorType::F32
        } else if shape.len() == 2 {
            self.weights.matrix_type()
        } else {
            TensorType::F16
        };
        self.plan.push(Planned {
            name,
            source,
            range,
            shape,
            ttype,
        });
    }

    /// A whole variable under a new name, keeping its shape.
    fn whole(&mut self, from: &str, to: String) -> Result<(), ConvertError> {
        let v = get(self.model, from)?;
        self.add(to, v, None, v.dims.clone());
        Ok(())
    }

    /// A layer norm: CT2's gamma/beta become weight/bias.
    fn norm(&mut self, from: &str, to: &str) -> Result<(), ConvertError> {
        self.whole(&format!("{from}/gamma"), format!("{to}.weight"))?;
        self.whole(&format!("{from}/beta"), format!("{to}.bias"))
    }

    /// A linear layer kept whole: weight and bias.
    fn linear(&mut self, from: &str, to: &str) -> Result<(), ConvertError> {
        self.whole(&format!("{from}/weight"), format!("{to}.weight"))?;
        self.whole(&format!("{from}/bias"), format!("{to}.bias"))
    }

    /// A fused projection whose weight stacks `parts` blocks of `s` rows: each named part gets its rows, and its
    /// bias slice unless the part has no bias in Whisper (the key projections, stored by CT2 as zeros).
    fn split(
        &mut self,
        from: &str,
        to: &str,
        parts: &[&str],
        s: usize,
    ) -> Result<(), ConvertError> {
        let n = parts.len();
        let w = get(self.model, &format!("{from}/weight"))?;
        let b = get(self.model, &format!("{from}/bias"))?;
        if w.dims != [n * s, s] || b.dims != [n * s] {
            return Err(layout(format!(
                "{} has shape {:?} and its bias {:?}; expected [{}, {s}]",
                w.name,
                w.dims,
                b.dims,
                n * s
            )));
        }
        for (k, part) in parts.iter().enumerate() {
            self.add(
                format!("{to}.{part}.weight"),
                w,
                Some((k * s * s, (k + 1) * s * s)),
                vec![s, s],
            );
            if *part != "key" {
                self.add(
                    format!("{to}.{part}.bias"),
                    b,
                    Some((k * s, (k + 1) * s)),
                    vec![s],
                );
            }
        }
        Ok(())
    }
}

impl Planner<'_> {
    /// A block's self-attention: its layer norm, the fused [query; key; value] projection split, the output.
    fn self_attention(&mut self, from: &str, to: &str, s: usize) -> Result<(), ConvertError> {
        self.norm(
            &format!("{from}/self_attention/layer_norm"),
            &format!("{to}.attn_ln"),
        )?;
        self.split(
            &format!("{from}/self_attention/linear_0"),
            &format!("{to}.attn"),
            &["query", "key", "value"],
            s,
        )?;
        self.linear(
            &format!("{from}/self_attention/linear_1"),
            &format!("{to}.attn.out"),
        )
    }

    /// A block's feed-forward part: layer norm and the two linear layers (PyTorch's mlp.0 and mlp.2).
    fn feed_forward(&mut self, from: &str, to: &str) -> Result<(), ConvertError> {
        self.norm(&format!("{from}/ffn/layer_norm"), &format!("{to}.mlp_ln"))?;
        self.linear(&format!("{from}/ffn/linear_0"), &format!("{to}.mlp.0"))?;
        self.linear(&format!("{from}/ffn/linear_1"), &format!("{to}.mlp.2"))
    }
}

/// Builds the ordered list of output tensors with whisper.cpp's names.
fn plan_tensors<'m>(
    model: &'m Ct2Model,
    hp: &Hparams,
    weights: Weights,
) -> Result<Vec<Planned<'m>>, ConvertError> {
    let mut p = Planner {
        model,
        weights,
        plan: Vec::new(),
    };
    for conv in ["conv1", "conv2"] {
        p.whole(
            &format!("encoder/{conv}/weight"),
            format!("encoder.{conv}.weight"),
        )?;
        // whisper.cpp holds the conv bias as a [1, state] tensor so it broadcasts over time.
        let b = get(model, &format!("encoder/{conv}/bias"))?;
        p.add(format!("encoder.{conv}.bias"), b, None, vec![b.len(), 1]);
    }
    p.whole(
        "encoder/position_encodings/encodings",
        "encoder.positional_embedding".into(),
    )?;
    for i in 0..hp.n_audio_layer {
        let (from, to) = (format!("encoder/layer_{i}"), format!("encoder.blocks.{i}"));
        p.self_attention(&from, &to, hp.n_audio_state as usize)?;
        p.feed_forward(&from, &to)?;
    }
    p.norm("encoder/layer_norm", "encoder.ln_post")?;

    p.whole(
        "decoder/embeddings/weight",
        "decoder.token_embedding.weight".into(),
    )?;
    p.whole(
        "decoder/position_encodings/encodings",
        "decoder.positional_embedding".into(),
    )?;
    for i in 0..hp.n_text_layer {
        let (from, to) = (format!("decoder/layer_{i}"), format!("decoder.blocks.{i}"));
        let s = hp.n_text_state as usize;
        p.self_attention(&from, &to, s)?;
        // Cross-attention: the query keeps its own projection, key and value are fused.
        p.norm(
            &format!("{from}/attention/layer_norm"),
            &format!("{to}.cross_attn_ln"),
        )?;
        p.linear(
            &format!("{from}/attention/linear_0"),
            &format!("{to}.cross_attn.query"),
        )?;
        p.split(
            &format!("{from}/attention/linear_1"),
            &format!("{to}.cross_attn"),
            &["key", "value"],
            s,
        )?;
        p.linear(
            &format!("{from}/attention/linear_2"),
            &format!("{to}.cross_attn.out"),
        )?;
        p.feed_forward(&from, &to)?;
    }
    p.norm("decoder/layer_norm", "decoder.ln")?;
    Ok(p.plan)
}
