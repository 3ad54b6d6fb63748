#!/usr/bin/env bash
# Installs llama-cpp-python with its OpenAI-compatible server into models/llm-server-venv (PyPI; pip compiles
# llama.cpp once, ~5 min, and keeps the wheel in its cache): the server the endpoint-mode test streams from, and the
# baseline of `llm-bench`. GGML_NATIVE is off: a -march=native build dies with SIGILL on virtual machines whose
# CPUs list AMX without allowing it (../shared/notes/llm-and-onnx-here.md).
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$root/models/llm-server-venv"
version="0.3.36"

if "$venv/bin/python" -c "import llama_cpp, llama_cpp.server; assert llama_cpp.__version__ == '$version'" 2>/dev/null; then
    echo "llm-server: llama-cpp-python $version is installed"
    exit 0
fi
echo "llm-server: installing llama-cpp-python[server] $version into $venv (compiles llama.cpp unless pip has the wheel)"
python3 -m venv "$venv"
CMAKE_ARGS="-DGGML_NATIVE=OFF" "$venv/bin/pip" install -q --disable-pip-version-check "llama-cpp-python[server]==$version"
