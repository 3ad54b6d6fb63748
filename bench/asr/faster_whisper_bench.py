"""faster-whisper baseline for `whisper-sat bench`: times greedy transcription of WAV clips on a CTranslate2 model.

Prints one JSON object per line: {"compute_type", "clip", "seconds", "runs_s": [...], "text"} and finally
{"peak_rss_mb"}. Settings mirror whisper-sat's: greedy (beam 1), English, no timestamps, no VAD, no context.
"""

import argparse
import json
import resource
import time
import wave

import numpy as np
from faster_whisper import WhisperModel


def load(path):
    with wave.open(path, "rb") as w:
        assert w.getsampwidth() == 2, path
        rate = w.getframerate()
        data = np.frombuffer(w.readframes(w.getnframes()), dtype=np.int16)
        if w.getnchannels() > 1:
            data = data.reshape(-1, w.getnchannels()).mean(axis=1)
    audio = data.astype(np.float32) / 32768.0
    if rate != 16000:
        # Linear interpolation is enough for timing; the text is only printed for reference.
        n = int(round(len(audio) * 16000 / rate))
        audio = np.interp(np.linspace(0, len(audio) - 1, n), np.arange(len(audio)), audio).astype(np.float32)
    return audio


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--model", required=True)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--compute-type", action="append", required=True)
    p.add_argument("clips", nargs="+")
    a = p.parse_args()
    clips = [(c, load(c)) for c in a.clips]
    for ct in a.compute_type:
        model = WhisperModel(a.model, device="cpu", compute_type=ct, cpu_threads=a.threads, num_workers=1)
        for path, audio in clips:
            runs, text = [], ""
            for i in range(a.runs + 1):
                t = time.perf_counter()
                segments, _ = model.transcribe(
                    audio, language="en", beam_size=1, best_of=1, temperature=0.0, without_timestamps=True,
                    vad_filter=False, condition_on_previous_text=False)
                text = " ".join(s.text.strip() for s in segments)
                if i > 0:  # the first run warms up
                    runs.append(time.perf_counter() - t)
            print(json.dumps({"compute_type": ct, "clip": path, "seconds": len(audio) / 16000,
                              "runs_s": runs, "text": text}), flush=True)
    print(json.dumps({"peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}), flush=True)


if __name__ == "__main__":
    main()
