#!/usr/bin/env bash
# Starts robot-agent with the embedded default configuration and one whisper-sat satellite beside it; Ctrl-C stops
# both. Used by `make run`.
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
trap 'kill $agent ${sat:-} 2>/dev/null; wait 2>/dev/null' EXIT INT TERM

# The satellite needs the token the server creates at first start.
for _ in $(seq 100); do
    [[ -s data/token ]] && break
    sleep 0.1
done
if [[ -x "$bin/whisper-sat" ]]; then
    # WHISPER_SAT_MODEL names a provisioned model (`make run MODEL=base`); the satellite's default is tiny.en.
    "$bin/whisper-sat" run --data-dir data --model "${WHISPER_SAT_MODEL:-tiny.en}" --language "$language" &
    sat=$!
fi
wait "$agent"
