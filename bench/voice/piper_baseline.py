"""voice-bench's baseline: PyPI's `piper-tts` speaking the same voice file as the agent's Piper engine.

Reads one JSON request per line on stdin ({"text": "..."}), synthesises it with `PiperVoice.synthesize` (one audio
chunk per sentence, as piper-tts streams), and answers one JSON line: milliseconds to the first chunk and to the
end, and the samples made. The voice loads once, before the first request; the last line reports the process's
peak RSS. Usage: piper_baseline.py VOICE.onnx VOICE.onnx.json
"""

import json
import resource
import sys
import time

from piper import PiperVoice


def main(model: str, config: str) -> None:
    started = time.perf_counter()
    voice = PiperVoice.load(model, config_path=config)
    load_ms = (time.perf_counter() - started) * 1000.0
    print(json.dumps({"ready": True, "load_ms": load_ms, "sample_rate": voice.config.sample_rate}), flush=True)
    for line in sys.stdin:
        request = json.loads(line)
        if request.get("quit"):
            break
        start = time.perf_counter()
        first_ms = None
        samples = 0
        for chunk in voice.synthesize(request["text"]):
            if first_ms is None:
                first_ms = (time.perf_counter() - start) * 1000.0
            samples += len(chunk.audio_int16_array)
        total_ms = (time.perf_counter() - start) * 1000.0
        print(json.dumps({"first_ms": first_ms, "total_ms": total_ms, "samples": samples}), flush=True)
    peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(json.dumps({"peak_rss_mb": peak_kb / 1024.0}), flush=True)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: piper_baseline.py VOICE.onnx VOICE.onnx.json")
    main(sys.argv[1], sys.argv[2])
