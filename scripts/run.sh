#!/usr/bin/env bash
# Starts robot-agent with the embedded default configuration, one whisper-sat satellite and one llm-sat satellite
# (the language model behind the rules' `chat(T)`) beside it; Ctrl-C stops them all. Used by `make run`.
set -euo pipefail

bin="${1:?usage: run.sh BIN_DIR}"
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

# AGENT_LANGUAGE=it (`make run LANGUAGE=it`) runs the agent on config/italian.toml and the satellite in Italian.
language="${AGENT_LANGUAGE:-en}"
config=()
if [[ "$language" == it ]]; then
    config=(--config config/italian.toml)
fi
"$bin/robot-agent" "${config[@]}" "${@:2}" &
agent=$!
trap 'kill $agent ${sat:-} ${llm:-} 2>/dev/null; wait 2>/dev/null' EXIT INT TERM

# The satellite needs the token the server creates at first start.
for _ in $(seq 100); do
    [[ -s data/token ]] && break
    sleep 0.1
done
if [[ -x "$bin/whisper-sat" ]]; then
    # WHISPER_SAT_MODEL names a provisioned model (`make run MODEL=base`); the satellite's default is tiny.en.
    # It hears the microphone less the agent's echo (the server's echo module), with its own-voice gate as the
    # second line for the moment before the canceller has found the echo (docs/voice.md, "Echo cancellation").
    "$bin/whisper-sat" run --data-dir data --model "${WHISPER_SAT_MODEL:-tiny.en}" --language "$language" --echo-gate &
    sat=$!
fi
if [[ -x "$bin/llm-sat" ]]; then
    # The default model (`make model-llm`); LLM_SAT_ARGS adds flags, e.g. `--endpoint http://gpu-box:8080/v1`.
    # shellcheck disable=SC2086
    "$bin/llm-sat" --data-dir data ${LLM_SAT_ARGS:-} &
    llm=$!
fi
wait "$agent"
