"""faster-whisper baseline for `asr-bench` (bench/asr): times transcription of WAV clips on a CTranslate2 model.

Prints one JSON object per line: {"compute_type", "beam", "clip", "seconds", "runs_s": [...], "text"} and finally
{"peak_rss_mb"}. Settings mirror whisper-sat's: greedy (beam 1) unless --beam-size says otherwise, the given
language, no timestamps, no VAD, no context, no temperature fallback.
"""

import argparse
import json
import resource
import time

from faster_whisper import WhisperModel, decode_audio


def load(path):
    # faster-whisper's own decoder and resampler (PyAV), as its users get them: the texts are scored for WER.
    return decode_audio(path, sampling_rate=16000)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--model", required=True)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--compute-type", action="append", required=True)
    p.add_argument("--beam-size", type=int, action="append")
    p.add_argument("--language", default="en")
    p.add_argument("clips", nargs="+")
    a = p.parse_args()
    clips = [(c, load(c)) for c in a.clips]
    for ct, beam in [(ct, b) for ct in a.compute_type for b in (a.beam_size or [1])]:
        model = WhisperModel(a.model, device="cpu", compute_type=ct, cpu_threads=a.threads, num_workers=1)
        for path, audio in clips:
            runs, text = [], ""
            for i in range(a.runs + 1):
                t = time.perf_counter()
                segments, _ = model.transcribe(
                    audio, language=a.language, beam_size=beam, best_of=1, temperature=0.0, without_timestamps=True,
                    vad_filter=False, condition_on_previous_text=False)
                text = " ".join(s.text.strip() for s in segments)
                if i > 0:  # the first run warms up
                    runs.append(time.perf_counter() - t)
            print(json.dumps({"compute_type": ct, "beam": beam, "clip": path, "seconds": len(audio) / 16000,
                              "runs_s": runs, "text": text}), flush=True)
    print(json.dumps({"peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}), flush=True)


if __name__ == "__main__":
    main()
