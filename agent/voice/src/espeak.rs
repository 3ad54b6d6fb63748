//! The one module that calls espeak-ng's C API: initialisation, voice and prosody settings, and synthesis
//! through the synchronous synth callback that hands over PCM buffers and the events inside them.
//!
//! espeak-ng keeps all of its state in C globals and is not thread safe, so an [`Espeak`] value is the
//! process-wide token for that state: at most one exists at a time (guarded by [`ENGINE_ALIVE`]), it is neither
//! `Send` nor `Sync`, and the engine thread in `engine.rs` is the only code that holds one.

// The workspace denies `unsafe_code`; this module is the FFI boundary to espeak-ng and needs it. Every block
// states why it is sound.
#![allow(unsafe_code)]

use std::ffi::{CStr, CString, c_char, c_int, c_short, c_void};
use std::marker::PhantomData;
use std::panic::{AssertUnwindSafe, catch_unwind, resume_unwind};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use espeak_rs_sys as sys;

use crate::error::VoiceError;

/// Set while an [`Espeak`] value exists, because espeak-ng's globals can only serve one owner.
static ENGINE_ALIVE: AtomicBool = AtomicBool::new(false);

/// espeak-ng copies the data path into a fixed buffer (`path_home`, 160 bytes on Linux); longer paths would be
/// truncated silently, so they are refused up front.
const MAX_DATA_PATH_BYTES: usize = 150;

/// What an espeak-ng event inside a PCM buffer says, reduced to what the voice crate uses.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum RawEventKind {
    /// A phoneme starts; the string is its IPA spelling (with stress marks), at most 8 bytes long.
    Phoneme(String),
    /// A word starts.
    Word,
    /// A sentence starts.
    Sentence,
    /// The end of the text was reached.
    End,
}

/// One event, positioned in samples from the start of the current `synthesize` call.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RawEvent {
    pub kind: RawEventKind,
    /// Sample index from the start of this synthesis call, as espeak-ng counts it while generating.
    pub sample: u64,
    /// The same position as espeak-ng rounds it to milliseconds (`audio_position`), kept to cross-check.
    pub audio_ms: u64,
}

/// Whether the callback wants espeak-ng to go on generating.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Flow {
    Continue,
    Abort,
}

/// How a synthesis call ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum SynthOutcome {
    Completed,
    Aborted,
}

/// A prosody parameter that espeak-ng accepts through `espeak_ng_SetParameter`.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Parameter {
    /// Words per minute.
    Rate,
    /// Base pitch, 0-100.
    Pitch,
    /// Pitch range (intonation), 0-100.
    Range,
    /// Volume, 0-200.
    Volume,
}

/// One clause of text as espeak-ng phonemised it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Clause {
    /// IPA with stress marks, words separated by spaces.
    pub ipa: String,
    /// The text espeak-ng read for this clause, its punctuation and the whitespace after it included.
    pub consumed: String,
}

/// The sink the callback forwards to, plus the events converted for it and a panic caught on the C side.
struct CallbackSlot<'a> {
    sink: &'a mut dyn FnMut(&[i16], &[RawEvent]) -> Flow,
    events: Vec<RawEvent>,
    panic: Option<Box<dyn std::any::Any + Send>>,
}

/// Ownership of espeak-ng's global state. Not `Send`: it must stay on the thread that created it.
#[derive(Debug)]
pub(crate) struct Espeak {
    sample_rate: u32,
    _not_send: PhantomData<*const ()>,
}

impl Espeak {
    /// Loads espeak-ng's data from `data_dir` and sets it up for synchronous synthesis with phoneme events in
    /// IPA, delivering PCM in buffers of `buffer_ms` milliseconds.
    pub(crate) fn initialize(data_dir: &Path, buffer_ms: u32) -> Result<Self, VoiceError> {
        if ENGINE_ALIVE.swap(true, Ordering::SeqCst) {
            return Err(VoiceError::EngineBusy);
        }
        // From here on the flag is ours. `engine` releases it in `Drop` on every early return below; its zero
        // sample rate tells `Drop` that there is nothing to terminate yet.
        let mut engine = Espeak {
            sample_rate: 0,
            _not_send: PhantomData,
        };
        let init_error = |message: String| VoiceError::Init {
            path: data_dir.to_path_buf(),
            message,
        };

        let path_text = data_dir
            .to_str()
            .ok_or_else(|| init_error("the path is not valid UTF-8".into()))?;
        if path_text.len() > MAX_DATA_PATH_BYTES {
            return Err(init_error(format!(
                "the path is longer than {MAX_DATA_PATH_BYTES} bytes"
            )));
        }
        let c_path = CString::new(path_text)
            .map_err(|_| init_error("the path contains a NUL byte".into()))?;
        let buffer_ms =
            c_int::try_from(buffer_ms).map_err(|_| init_error("buffer length too large".into()))?;

        // SAFETY: `c_path` is a valid NUL-terminated string that outlives the call; espeak-ng copies it into
        // its own buffer (length checked above). We hold the process-wide engine flag, so no other thread
        // touches espeak-ng's globals concurrently.
        unsafe { sys::espeak_ng_InitializePath(c_path.as_ptr()) };

        let mut context: sys::espeak_ng_ERROR_CONTEXT = std::ptr::null_mut();
        // SAFETY: `context` is a valid out-pointer; espeak-ng either leaves it null or allocates a context
        // that we release with `espeak_ng_ClearErrorContext` below.
        let status = unsafe { sys::espeak_ng_Initialize(&mut context) };
        if !context.is_null() {
            // SAFETY: `context` was allocated by espeak-ng in the call above and is released exactly once.
            unsafe { sys::espeak_ng_ClearErrorContext(&mut context) };
        }
        check(status).map_err(init_error)?;

        // SAFETY: espeak-ng is initialised (status checked); a null device is allowed in synchronous mode,
        // which never opens an audio device.
        let status = unsafe {
            sys::espeak_ng_InitializeOutput(
                sys::espeak_ng_OUTPUT_MODE_ENOUTPUT_MODE_SYNCHRONOUS,
                buffer_ms,
                std::ptr::null(),
            )
        };
        check(status).map_err(init_error)?;

        // SAFETY: plain setters on the initialised engine. `on_synth` has the exact signature of
        // `t_espeak_callback` and stays valid for the whole program.
        let (status, sample_rate) = unsafe {
            sys::espeak_SetSynthCallback(Some(on_synth));
            let status = sys::espeak_ng_SetPhonemeEvents(1, 1);
            (status, sys::espeak_ng_GetSampleRate())
        };
        check(status).map_err(init_error)?;
        engine.sample_rate = u32::try_from(sample_rate)
            .map_err(|_| init_error(format!("invalid sample rate {sample_rate}")))?;
        Ok(engine)
    }

    /// The rate of the PCM espeak-ng produces (22050 Hz with the standard data).
    pub(crate) fn sample_rate(&self) -> u32 {
        self.sample_rate
    }

    /// Selects a voice by espeak-ng name or language (`en`, `en-us`, `it`, `en+f3`).
    pub(crate) fn set_voice(&mut self, name: &str) -> Result<(), VoiceError> {
        let not_found = |message: String| VoiceError::VoiceNotFound {
            voice: name.to_owned(),
            message,
        };
        let c_name =
            CString::new(name).map_err(|_| not_found("the name contains a NUL byte".into()))?;
        // SAFETY: `c_name` is NUL-terminated and outlives the call; `&mut self` proves we own the engine.
        let status = unsafe { sys::espeak_ng_SetVoiceByName(c_name.as_ptr()) };
        check(status).map_err(not_found)
    }

    /// Sets an absolute value of a prosody parameter for the following synthesis calls.
    pub(crate) fn set_parameter(
        &mut self,
        parameter: Parameter,
        value: u32,
    ) -> Result<(), VoiceError> {
        let id = match parameter {
            Parameter::Rate => sys::espeak_PARAMETER_espeakRATE,
            Parameter::Pitch => sys::espeak_PARAMETER_espeakPITCH,
            Parameter::Range => sys::espeak_PARAMETER_espeakRANGE,
            Parameter::Volume => sys::espeak_PARAMETER_espeakVOLUME,
        };
        let value = c_int::try_from(value).map_err(|_| VoiceError::InvalidSetting {
            name: "parameter",
            value: value.to_string(),
            reason: "too large".into(),
        })?;
        // SAFETY: a plain setter on the initialised engine, which `&mut self` proves we own.
        let status = unsafe { sys::espeak_ng_SetParameter(id, value, 0) };
        check(status).map_err(VoiceError::Synthesis)
    }

    /// Turns `text` (UTF-8) into IPA phonemes with the current voice, one string per clause as espeak-ng reads
    /// the text, each with the part of the text it consumed (from which the caller takes the clause's
    /// punctuation). This is how Piper voices are fed: they were trained on espeak-ng's IPA.
    pub(crate) fn text_to_phonemes(&mut self, text: &str) -> Result<Vec<Clause>, VoiceError> {
        let c_text = CString::new(text)
            .map_err(|_| VoiceError::InvalidText("it contains a NUL character".into()))?;
        let start = c_text.as_ptr();
        let end_offset = c_text.as_bytes().len();
        let mut cursor: *const c_void = start.cast::<c_void>();
        let mut clauses = Vec::new();
        let mut consumed_from = 0usize;
        // espeak-ng returns one clause per call and moves `cursor` past it, or sets it to null at the end; a
        // bound on the calls guards against a cursor that stops moving.
        for _ in 0..=end_offset {
            if cursor.is_null() {
                break;
            }
            // SAFETY: `cursor` points into `c_text` (a NUL-terminated UTF-8 string alive for this whole loop), as
            // set by the previous call or at its start; espeak-ng reads from there and writes the position after
            // the clause, or null, back through the pointer we pass. `&mut self` proves we own the engine. The
            // returned string is espeak-ng's own static buffer, copied below before the next call.
            let phonemes = unsafe {
                sys::espeak_TextToPhonemes(
                    &mut cursor,
                    sys::espeakCHARS_UTF8 as c_int,
                    sys::espeakPHONEMES_IPA as c_int,
                )
            };
            let ipa = if phonemes.is_null() {
                String::new()
            } else {
                // SAFETY: a non-null result is a NUL-terminated string in espeak-ng's buffer, valid until the
                // next call; it is copied at once.
                unsafe { CStr::from_ptr(phonemes) }
                    .to_string_lossy()
                    .into_owned()
            };
            let consumed_to = if cursor.is_null() {
                end_offset
            } else {
                // The cursor still points into `c_text`: its distance from the start is a byte offset.
                (cursor as usize)
                    .saturating_sub(start as usize)
                    .min(end_offset)
            };
            let consumed = text
                .get(consumed_from..consumed_to.max(consumed_from))
                .unwrap_or_default()
                .to_owned();
            consumed_from = consumed_to.max(consumed_from);
            clauses.push(Clause { ipa, consumed });
        }
        Ok(clauses)
    }

    /// Synthesises `text` (UTF-8), calling `sink` with every PCM buffer and the events positioned inside it;
    /// a final call with an empty buffer marks the end. The sink returns [`Flow::Abort`] to stop early.
    pub(crate) fn synthesize(
        &mut self,
        text: &str,
        sink: &mut dyn FnMut(&[i16], &[RawEvent]) -> Flow,
    ) -> Result<SynthOutcome, VoiceError> {
        let c_text = CString::new(text)
            .map_err(|_| VoiceError::InvalidText("it contains a NUL character".into()))?;
        let mut slot = CallbackSlot {
            sink,
            events: Vec::with_capacity(32),
            panic: None,
        };
        let slot_ptr: *mut CallbackSlot<'_> = &mut slot;
        // `espeakENDPAUSE` keeps the pause that ends a sentence; without it, sentences synthesised one by one
        // would run into each other.
        // SAFETY: `c_text` is a NUL-terminated UTF-8 string (flag `espeakCHARS_UTF8`) alive for the call. The
        // user-data pointer refers to `slot`, which lives on this stack frame until the call returns;
        // synchronous mode runs every callback on this thread before `espeak_ng_Synthesize` returns, so the
        // pointer is never used after `slot` is gone, and nothing else accesses `slot` meanwhile.
        let status = unsafe {
            sys::espeak_ng_Synthesize(
                c_text.as_ptr().cast::<c_void>(),
                c_text.as_bytes_with_nul().len(),
                0,
                sys::espeak_POSITION_TYPE_POS_CHARACTER,
                0,
                sys::espeakCHARS_UTF8 | sys::espeakENDPAUSE,
                std::ptr::null_mut(),
                slot_ptr.cast::<c_void>(),
            )
        };
        if let Some(payload) = slot.panic.take() {
            resume_unwind(payload);
        }
        match status {
            sys::espeak_ng_STATUS_ENS_OK => Ok(SynthOutcome::Completed),
            sys::espeak_ng_STATUS_ENS_SPEECH_STOPPED => Ok(SynthOutcome::Aborted),
            other => Err(VoiceError::Synthesis(status_message(other))),
        }
    }
}

impl Drop for Espeak {
    fn drop(&mut self) {
        if self.sample_rate != 0 {
            // SAFETY: the engine was fully initialised (non-zero sample rate) and is terminated once, on the
            // thread that owns it.
            unsafe { sys::espeak_ng_Terminate() };
        }
        ENGINE_ALIVE.store(false, Ordering::SeqCst);
    }
}

/// The C callback espeak-ng calls with each PCM buffer (null at the end) and a terminated event list.
extern "C" fn on_synth(
    wav: *mut c_short,
    numsamples: c_int,
    events: *mut sys::espeak_EVENT,
) -> c_int {
    if events.is_null() {
        return 1;
    }
    // SAFETY: espeak-ng always passes a list of at least one event (the terminator), and it sets `user_data`
    // on every entry to the pointer given to `espeak_ng_Synthesize`, which is our live `CallbackSlot`.
    let slot = unsafe { (*events).user_data.cast::<CallbackSlot<'_>>() };
    if slot.is_null() {
        return 1;
    }
    // SAFETY: see above: the slot outlives the synthesis call and only this callback touches it meanwhile.
    let slot = unsafe { &mut *slot };
    if slot.panic.is_some() {
        return 1;
    }

    slot.events.clear();
    let mut cursor = events;
    loop {
        // SAFETY: the list ends with an `espeakEVENT_LIST_TERMINATED` entry, and we stop at it, so `cursor`
        // stays inside the array espeak-ng passed.
        let event = unsafe { &*cursor };
        if event.type_ == sys::espeak_EVENT_TYPE_espeakEVENT_LIST_TERMINATED {
            break;
        }
        if let Some(raw) = convert_event(event) {
            slot.events.push(raw);
        }
        // SAFETY: the current entry is not the terminator, so the next one exists.
        cursor = unsafe { cursor.add(1) };
    }

    let pcm: &[i16] = match usize::try_from(numsamples) {
        // SAFETY: espeak-ng hands a buffer of `numsamples` 16-bit samples that stays valid during the call.
        Ok(len) if !wav.is_null() && len > 0 => unsafe { std::slice::from_raw_parts(wav, len) },
        _ => &[],
    };
    let CallbackSlot {
        sink,
        events,
        panic,
    } = slot;
    match catch_unwind(AssertUnwindSafe(|| sink(pcm, events))) {
        Ok(Flow::Continue) => 0,
        Ok(Flow::Abort) => 1,
        Err(payload) => {
            // A panic must not unwind into C; keep it and re-raise it once espeak-ng has returned.
            *panic = Some(payload);
            1
        }
    }
}

/// Converts one C event; events the voice crate does not use come back as `None`.
fn convert_event(event: &sys::espeak_EVENT) -> Option<RawEvent> {
    let kind = match event.type_ {
        sys::espeak_EVENT_TYPE_espeakEVENT_PHONEME => {
            // SAFETY: for phoneme events espeak-ng fills the `string` member of the union (up to 8 bytes of
            // UTF-8, NUL-terminated when shorter), and every bit pattern is a valid `[c_char; 8]`.
            let bytes = unsafe { event.id.string };
            Some(RawEventKind::Phoneme(phoneme_text(&bytes)))
        }
        sys::espeak_EVENT_TYPE_espeakEVENT_WORD => Some(RawEventKind::Word),
        sys::espeak_EVENT_TYPE_espeakEVENT_SENTENCE => Some(RawEventKind::Sentence),
        sys::espeak_EVENT_TYPE_espeakEVENT_END => Some(RawEventKind::End),
        _ => None,
    }?;
    Some(RawEvent {
        kind,
        sample: u64::try_from(event.sample).unwrap_or(0),
        audio_ms: u64::try_from(event.audio_position).unwrap_or(0),
    })
}

/// Reads the up-to-8-byte phoneme name; a multi-byte character cut by the 8-byte limit is dropped.
fn phoneme_text(raw: &[c_char; 8]) -> String {
    let bytes: Vec<u8> = raw
        .iter()
        .map(|&c| c.to_ne_bytes()[0])
        .take_while(|&b| b != 0)
        .collect();
    match std::str::from_utf8(&bytes) {
        Ok(text) => text.to_owned(),
        Err(error) => String::from_utf8_lossy(&bytes[..error.valid_up_to()]).into_owned(),
    }
}

fn check(status: sys::espeak_ng_STATUS) -> Result<(), String> {
    if status == sys::espeak_ng_STATUS_ENS_OK {
        Ok(())
    } else {
        Err(status_message(status))
    }
}

/// espeak-ng's own text for a status code.
fn status_message(status: sys::espeak_ng_STATUS) -> String {
    let mut buffer = [0 as c_char; 256];
    // SAFETY: the buffer is writable for its full length, which is what we pass; espeak-ng NUL-terminates.
    unsafe { sys::espeak_ng_GetStatusCodeMessage(status, buffer.as_mut_ptr(), buffer.len()) };
    // SAFETY: the buffer was zero-initialised and espeak-ng writes a NUL-terminated string within it.
    let text = unsafe { CStr::from_ptr(buffer.as_ptr()) };
    format!("{} (status {status:#x})", text.to_string_lossy())
}
