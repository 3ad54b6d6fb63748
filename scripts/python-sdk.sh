#!/usr/bin/env bash
# Creates the Python SDK's virtual environment (satellites/python/.venv) and installs into it what the SDK's tests
# and benchmark use: the SDK itself, built from satellites/python by pip with maturin (as a user installs it),
# pytest (with pytest-timeout) and numpy; and the Python tools the Rust integration tests check files and formats
# with. Re-running rebuilds the SDK incrementally (cargo's cache), so a changed binding is what runs.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
venv=satellites/python/.venv
if [[ ! -x $venv/bin/python ]]; then
    python3 -m venv "$venv"
fi
# pytest and numpy (and mcap, the reader tests/record.rs checks recordings with) only once; pip answers quickly when
# they are present.
"$venv/bin/python" -c "import pytest, numpy, mcap" 2>/dev/null || "$venv/bin/pip" install -q 'pytest>=8' 'numpy>=1.24' 'mcap>=1.2'
# pytest-timeout: the suite's per-test ceiling (satellites/python/pyproject.toml, [tool.pytest.ini_options]).
"$venv/bin/python" -c "import pytest_timeout" 2>/dev/null || "$venv/bin/pip" install -q 'pytest-timeout>=2.3'
# Prometheus's own Python client: the metrics test parses /metrics with its exposition-format parser.
"$venv/bin/python" -c "import prometheus_client" 2>/dev/null || "$venv/bin/pip" install -q 'prometheus-client>=0.20'
# eclipse-zenoh: a plain Zenoh client joining the federation (tests/test_zenoh.py), the version of the hub's zenoh crate.
"$venv/bin/python" -c "import zenoh" 2>/dev/null || "$venv/bin/pip" install -q 'eclipse-zenoh==1.10.2'
"$venv/bin/pip" install -q --force-reinstall --no-deps ./satellites/python
