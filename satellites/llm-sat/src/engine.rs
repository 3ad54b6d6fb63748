//! The local generator: llama.cpp in-process (crate `llama-cpp-2`) on any GGUF file. It keeps the tokens whose keys
//! and values are in its cache, so a prompt that starts like the previous one (the system prompt, the conversation
//! so far) decodes only what is new; a conversation whose oldest turns were dropped is found further on in the cache
//! and moved down rather than read again.

use std::num::NonZeroU32;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use llama_cpp_2::context::LlamaContext;
use llama_cpp_2::context::params::LlamaContextParams;
use llama_cpp_2::llama_backend::LlamaBackend;
use llama_cpp_2::llama_batch::LlamaBatch;
use llama_cpp_2::model::params::LlamaModelParams;
use llama_cpp_2::model::{LlamaChatMessage, LlamaChatTemplate, LlamaModel};
use llama_cpp_2::sampling::LlamaSampler;
use llama_cpp_2::token::LlamaToken;
use llama_cpp_2::token::logit_bias::LlamaLogitBias;

use crate::generator::{
    Constraint, Ended, Flow, GenerateError, Generated, Generator, Limits, Message,
};

/// How the local model is run.
#[derive(Debug, Clone)]
pub struct EngineOptions {
    /// Threads for the prompt and for each generated token.
    pub threads: u32,
    /// Tokens the context holds (prompt and reply together).
    pub context: u32,
    /// 0 samples greedily (the same reply every time); above 0, that temperature with top-k 40 and top-p 0.95.
    pub temperature: f32,
    pub seed: u32,
    /// A free reply (no grammar) holds at least this many tokens: the model's end-of-generation tokens are masked
    /// until then. 0 lets the model end when it likes; tests and benches that must interrupt or time a long
    /// generation set it (as vLLM's `min_tokens`).
    pub min_tokens: u32,
}

/// Tokens decoded per batch while reading a prompt.
const BATCH: usize = 512;

/// llama.cpp with one model and one context.
pub struct Engine {
    // Declared before `model`: the context borrows it, and is dropped first.
    context: LlamaContext<'static>,
    model: &'static LlamaModel,
    template: LlamaChatTemplate,
    name: String,
    options: EngineOptions,
    /// The tokens whose keys and values the context holds, in order from position 0.
    cached: Vec<LlamaToken>,
}

impl std::fmt::Debug for Engine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Engine")
            .field("model", &self.name)
            .field("cached", &self.cached.len())
            .finish_non_exhaustive()
    }
}

/// Why the model could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    #[error("{path}: no such model file (the default one is provisioned by `make model-llm`)")]
    Missing { path: String },
    #[error("{path}: llama.cpp cannot load it: {reason}")]
    Load { path: String, reason: String },
}

impl Engine {
    /// Loads `path` once for the life of the process (the model and llama.cpp's backend are never freed: a
    /// satellite serves one model until it exits).
    pub fn load(path: &Path, options: EngineOptions) -> Result<Engine, LoadError> {
        let shown = path.display().to_string();
        if !path.is_file() {
            return Err(LoadError::Missing { path: shown });
        }
        let load = |reason: String| LoadError::Load {
            path: shown.clone(),
            reason,
        };
        let backend = backend().map_err(load)?;
        let model = LlamaModel::load_from_file(backend, path, &LlamaModelParams::default())
            .map_err(|e| load(e.to_string()))?;
        let model: &'static LlamaModel = Box::leak(Box::new(model));
        let template = model
            .chat_template(None)
            .map_err(|e| load(format!("no chat template: {e}")))?;
        let threads = i32::try_from(options.threads.max(1)).unwrap_or(1);
        let params = LlamaContextParams::default()
            .with_n_ctx(NonZeroU32::new(options.context.max(256)))
            .with_n_batch(BATCH as u32)
            .with_n_threads(threads)
            .with_n_threads_batch(threads);
        let context = model
            .new_context(backend, params)
            .map_err(|e| load(e.to_string()))?;
        let name = path
            .file_stem()
            .map_or_else(|| shown.clone(), |s| s.to_string_lossy().into_owned());
        Ok(Engine {
            context,
            model,
            template,
            name,
            options,
            cached: Vec::new(),
        })
    }

    /// The sampler chain for one reply; with `end_masked`, the model's end-of-generation tokens cannot be drawn.
    fn sampler(
        &self,
        constraint: Option<&Constraint>,
        end_masked: bool,
    ) -> Result<LlamaSampler, GenerateError> {
        let mut chain = Vec::new();
        if end_masked {
            let vocab = self.model.vocab();
            let ends: Vec<LlamaLogitBias> = (0..self.model.n_vocab())
                .map(LlamaToken)
                .filter(|&token| vocab.is_eog(token))
                .map(|token| LlamaLogitBias::new(token, f32::NEG_INFINITY))
                .collect();
            chain.push(LlamaSampler::logit_bias(self.model.n_vocab(), &ends));
        }
        if let Some(constraint) = constraint {
            let grammar = LlamaSampler::grammar(self.model, &constraint.gbnf, "root")
                .map_err(|e| GenerateError::Model(format!("grammar: {e}")))?;
            chain.push(grammar);
        }
        // A mild penalty on repeats: small models otherwise loop on a phrase.
        chain.push(LlamaSampler::penalties(
            self.model.n_vocab(),
            64,
            1.1,
            0.0,
            0.0,
        ));
        if self.options.temperature > 0.0 {
            chain.push(LlamaSampler::top_k(40));
            chain.push(LlamaSampler::top_p(0.95, 1));
            chain.push(LlamaSampler::temp(self.options.temperature));
            chain.push(LlamaSampler::dist(self.options.seed));
        } else {
            chain.push(LlamaSampler::greedy());
        }
        Ok(LlamaSampler::chain_simple(chain))
    }

    /// Makes the context hold `prompt`: keeps the longest prefix already cached, decodes the rest. Returns how
    /// many tokens came from the cache.
    fn feed_prompt(
        &mut self,
        prompt: &[LlamaToken],
        cancel: &AtomicBool,
    ) -> Result<Option<usize>, GenerateError> {
        let mut keep = common_prefix(&self.cached, prompt);
        // A conversation trimmed at its start (the brain drops its oldest turns when the memory is full) continues
        // further on in the cache: the turns dropped are removed from the cache and the rest moved down to follow
        // the kept prefix (llama.cpp re-rotates their keys), instead of decoding the whole conversation again.
        if let Some(from) = continues_after(&self.cached, prompt, keep) {
            let moved = self
                .context
                .kv_cache_seq_rm(0, Some(keep as u32), Some(from as u32))
                .is_ok()
                && self
                    .context
                    .kv_cache_seq_add(0, Some(from as u32), None, -((from - keep) as i32))
                    .is_ok();
            if moved {
                self.cached.drain(keep..from);
                keep = common_prefix(&self.cached, prompt);
            }
        }
        // The last prompt token is always decoded again: its logits give the first reply token.
        keep = keep.min(prompt.len().saturating_sub(1));
        if self
            .context
            .kv_cache_seq_rm(0, Some(keep as u32), None)
            .is_err()
        {
            // Some caches cannot drop a tail: start from nothing.
            self.context.clear_kv_cache();
            keep = 0;
        }
        self.cached.truncate(keep);
        let mut batch = LlamaBatch::new(BATCH, 1);
        let last = prompt.len() - 1;
        for (chunk_start, chunk) in prompt[keep..].chunks(BATCH).enumerate() {
            if cancel.load(Ordering::Relaxed) {
                return Ok(None);
            }
            batch.clear();
            for (i, token) in chunk.iter().enumerate() {
                let pos = keep + chunk_start * BATCH + i;
                batch
                    .add(*token, pos as i32, &[0], pos == last)
                    .map_err(|e| GenerateError::Model(e.to_string()))?;
            }
            self.context
                .decode(&mut batch)
                .map_err(|e| GenerateError::Model(e.to_string()))?;
            self.cached.extend_from_slice(chunk);
        }
        Ok(Some(keep))
    }

    fn tokens_of(&self, chat: &[Message]) -> Result<Vec<LlamaToken>, GenerateError> {
        let text = self.render(chat)?;
        Ok(self.model.vocab().tokenize(text.as_bytes(), false, true))
    }
}

/// llama.cpp's backend, initialised once per process.
pub(crate) fn backend() -> Result<&'static LlamaBackend, String> {
    static BACKEND: std::sync::OnceLock<Result<LlamaBackend, String>> = std::sync::OnceLock::new();
    BACKEND
        .get_or_init(|| {
            let mut backend = LlamaBackend::init().map_err(|e| e.to_string())?;
            backend.void_logs();
            Ok(backend)
        })
        .as_ref()
        .map_err(Clone::clone)
}

impl Generator for Engine {
    fn model(&self) -> &str {
        &self.name
    }

    fn render(&self, chat: &[Message]) -> Result<String, GenerateError> {
        let messages = chat
            .iter()
            .map(|m| LlamaChatMessage::new(m.speaker.role().to_owned(), m.content.clone()))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| GenerateError::Model(format!("a message holds a NUL byte: {e}")))?;
        self.model
            .apply_chat_template(&self.template, &messages, true)
            .map_err(|e| GenerateError::Model(format!("chat template: {e}")))
    }

    fn generate(
        &mut self,
        chat: &[Message],
        constraint: Option<&Constraint>,
        limits: Limits,
        cancel: &AtomicBool,
        on_piece: &mut dyn FnMut(&str) -> Flow,
    ) -> Result<Generated, GenerateError> {
        let started = Instant::now();
        let prompt = self.tokens_of(chat)?;
        let context = self.context.n_ctx();
        if prompt.is_empty() || prompt.len() + 8 > context as usize {
            return Err(GenerateError::PromptTooLong {
                tokens: prompt.len(),
                context,
            });
        }
        let mut sampler = self.sampler(constraint, false)?;
        // Until `min_tokens`, a second chain that cannot end draws the tokens; the first is told each one, so its
        // repeat penalty sees the whole reply.
        let mut held = match constraint {
            None if self.options.min_tokens > 0 => Some(self.sampler(None, true)?),
            _ => None,
        };
        let mut generated = Generated {
            ended: Ended::Cancelled,
            prompt_tokens: prompt.len() as u32,
            cached_tokens: 0,
            tokens: 0,
            first_token: None,
        };
        let Some(cached) = self.feed_prompt(&prompt, cancel)? else {
            return Ok(generated);
        };
        generated.cached_tokens = cached as u32;
        let vocab = self.model.vocab();
        let mut pending: Vec<u8> = Vec::new();
        let mut batch = LlamaBatch::new(1, 1);
        let mut logits_at = (prompt.len() - 1 - cached) as i32 % BATCH as i32;
        let room = context as usize - prompt.len();
        let max_tokens = (limits.max_tokens as usize).min(room);
        generated.ended = loop {
            if cancel.load(Ordering::Relaxed) {
                break Ended::Cancelled;
            }
            if Instant::now() >= limits.deadline {
                break Ended::Deadline;
            }
            if generated.tokens as usize >= max_tokens {
                break Ended::MaxTokens;
            }
            let token = match held.as_mut() {
                Some(chain) if generated.tokens < self.options.min_tokens => {
                    let token = chain.sample(&self.context, logits_at);
                    sampler.accept(token);
                    token
                }
                _ => sampler.sample(&self.context, logits_at),
            };
            if vocab.is_eog(token) {
                break Ended::EndOfText;
            }
            generated.tokens += 1;
            generated
                .first_token
                .get_or_insert_with(|| started.elapsed());
            pending.extend(vocab.token_to_piece(token, false, None));
            let flow = match complete_utf8(&pending) {
                0 => Flow::Continue,
                n => {
                    let flow = on_piece(&String::from_utf8_lossy(&pending[..n]));
                    pending.drain(..n);
                    flow
                }
            };
            if flow == Flow::Stop {
                break Ended::Stopped;
            }
            let pos = self.cached.len();
            batch.clear();
            batch
                .add(token, pos as i32, &[0], true)
                .map_err(|e| GenerateError::Model(e.to_string()))?;
            self.context
                .decode(&mut batch)
                .map_err(|e| GenerateError::Model(e.to_string()))?;
            self.cached.push(token);
            logits_at = 0;
        };
        Ok(generated)
    }
}

/// How many leading tokens `a` and `b` share.
fn common_prefix<T: PartialEq>(a: &[T], b: &[T]) -> usize {
    a.iter().zip(b).take_while(|(x, y)| x == y).count()
}

/// Fewest tokens a cut-out part of the cache must give back to be worth moving the rest of the cache for.
const MIN_CONTINUED: usize = 32;

/// Where in `cached`, past the shared prefix `keep`, the rest of `prompt` continues: the start of the longest run
/// (at least [`MIN_CONTINUED`] tokens) equal to `prompt[keep..]`'s beginning. `None` when no such run exists.
fn continues_after<T: PartialEq>(cached: &[T], prompt: &[T], keep: usize) -> Option<usize> {
    let rest = prompt.get(keep..)?;
    if rest.len() < MIN_CONTINUED {
        return None;
    }
    (keep + 1..cached.len().saturating_sub(MIN_CONTINUED - 1))
        .filter(|&from| cached[from] == rest[0])
        .map(|from| (from, common_prefix(&cached[from..], rest)))
        .filter(|&(_, run)| run >= MIN_CONTINUED)
        .max_by_key(|&(from, run)| (run, std::cmp::Reverse(from)))
        .map(|(from, _)| from)
}

/// How many leading bytes of `bytes` are whole UTF-8 characters (a token may end inside a character).
fn complete_utf8(bytes: &[u8]) -> usize {
    match std::str::from_utf8(bytes) {
        Ok(_) => bytes.len(),
        Err(e) if e.error_len().is_none() => e.valid_up_to(),
        // Invalid bytes, not a cut: hand them on (they become U+FFFD).
        Err(_) => bytes.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_conversation_trimmed_at_its_start_is_found_further_on_in_the_cache() {
        // system prompt (0..10), turns 1..4 of 40 tokens each; the trimmed prompt keeps turns 3 and 4 and adds one.
        let system: Vec<u32> = (0..10).collect();
        let turn = |n: u32| -> Vec<u32> { (0..40).map(|i| 1000 * n + i).collect() };
        let cached = [system.clone(), turn(1), turn(2), turn(3), turn(4)].concat();
        let prompt = [system.clone(), turn(3), turn(4), turn(5)].concat();
        let keep = common_prefix(&cached, &prompt);
        assert_eq!(keep, 10);
        let from = continues_after(&cached, &prompt, keep).expect("turns 3 and 4 are cached");
        assert_eq!(from, 10 + 80);
        let mut moved = cached.clone();
        moved.drain(keep..from);
        assert_eq!(common_prefix(&moved, &prompt), 10 + 80);
    }

    #[test]
    fn a_short_or_absent_continuation_moves_nothing() {
        let cached: Vec<u32> = (0..200).collect();
        // Nothing of the rest is cached.
        let other: Vec<u32> = (0..10).chain(5000..5100).collect();
        assert_eq!(continues_after(&cached, &other, 10), None);
        // Only a few tokens of it are: not worth moving the cache.
        let few: Vec<u32> = (0..10).chain(50..60).chain(7000..7100).collect();
        assert_eq!(continues_after(&cached, &few, 10), None);
        // The prompt is the cache's own beginning: nothing after it to find.
        assert_eq!(continues_after(&cached, &cached[..150], 150), None);
    }

    #[test]
    fn a_character_cut_between_tokens_waits_for_its_end() {
        let euro = "€".as_bytes();
        assert_eq!(complete_utf8(&euro[..2]), 0);
        assert_eq!(complete_utf8(euro), 3);
        let mut text = b"ab".to_vec();
        text.extend_from_slice(&euro[..1]);
        assert_eq!(complete_utf8(&text), 2);
        assert_eq!(complete_utf8(&[0xff, b'a']), 2);
    }
}
