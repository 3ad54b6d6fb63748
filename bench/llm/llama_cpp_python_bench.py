"""llm-bench's baseline: PyPI's `llama-cpp-python` generating from the same GGUF file as llm-sat's engine.

Loads the model once (n_ctx 2048, 2 threads for the prompt and for each token), prints a ready line, then reads one
JSON request per line on stdin ({"messages": [{"role": ..., "content": ...}], "max_tokens": N}) and answers one JSON
line per request: seconds from the call to the first streamed chunk with text, seconds from that chunk to the last
one, the tokens generated, the prompt tokens, why it ended and the text. Sampling is greedy (temperature 0, top-k 1)
with the repeat penalty llm-sat's engine applies (1.1 over the last 64 tokens), so both sides pick tokens alike.
At the end of stdin (or on {"quit": true}) the last line reports the process's peak RSS (VmHWM).
Usage: llama_cpp_python_bench.py MODEL.gguf THREADS
"""

import json
import sys
import time

import llama_cpp
from llama_cpp.llama_chat_format import Jinja2ChatFormatter

CONTEXT = 2048
# llm-sat's engine: LlamaSampler::penalties(n_vocab, 64, 1.1, 0, 0). Llama's last_n_tokens_size defaults to 64.
REPEAT_PENALTY = 1.1


def peak_rss_kb() -> int:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmHWM:"):
                return int(line.split()[1])
    return 0


def prompt_counter(llm: "llama_cpp.Llama"):
    """The prompt's token count as create_chat_completion builds it (the GGUF's own chat template), or None when
    the model carries no template this version can render."""
    template = llm.metadata.get("tokenizer.chat_template")
    if not template:
        return lambda messages: None
    vocab = llm._model
    formatter = Jinja2ChatFormatter(
        template=template,
        eos_token=vocab.token_get_text(vocab.token_eos()),
        bos_token=vocab.token_get_text(vocab.token_bos()),
    )

    def count(messages):
        rendered = formatter(messages=messages)
        return len(llm.tokenize(rendered.prompt.encode("utf-8"), add_bos=not rendered.added_special, special=True))

    return count


def main(model: str, threads: int) -> None:
    started = time.perf_counter()
    llm = llama_cpp.Llama(
        model_path=model, n_ctx=CONTEXT, n_threads=threads, n_threads_batch=threads, verbose=False
    )
    load_s = time.perf_counter() - started
    count_prompt = prompt_counter(llm)
    print(json.dumps({"ready": True, "load_s": load_s, "version": llama_cpp.__version__}), flush=True)
    for line in sys.stdin:
        request = json.loads(line)
        if request.get("quit"):
            break
        messages = request["messages"]
        max_tokens = request["max_tokens"]
        start = time.perf_counter()
        first = last = None
        text = []
        finish = None
        for chunk in llm.create_chat_completion(
            messages=messages,
            max_tokens=max_tokens,
            temperature=0.0,
            top_k=1,
            repeat_penalty=REPEAT_PENALTY,
            stream=True,
        ):
            choice = chunk["choices"][0]
            piece = choice["delta"].get("content")
            if piece:
                last = time.perf_counter()
                if first is None:
                    first = last
                text.append(piece)
            finish = choice.get("finish_reason") or finish
        text = "".join(text)
        # A streamed chunk may hold more than one token (text held back while it could start a stop string), so the
        # count is the limit when generation hit it, and the text's tokens otherwise.
        if finish == "length":
            tokens = max_tokens
        else:
            tokens = len(llm.tokenize(text.encode("utf-8"), add_bos=False, special=False))
        print(
            json.dumps(
                {
                    "first_token_s": None if first is None else first - start,
                    "decode_s": None if first is None else last - first,
                    "tokens": tokens,
                    "prompt_tokens": count_prompt(messages),
                    "cached_tokens": None,
                    "ended": finish,
                    "text": text,
                }
            ),
            flush=True,
        )
    print(json.dumps({"peak_rss_kb": peak_rss_kb()}), flush=True)


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
