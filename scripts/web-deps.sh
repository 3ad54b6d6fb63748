#!/usr/bin/env bash
# Installs the page's npm dependencies (three.js, and TypeScript with Node's types for `make test`'s type check of
# the page's pure modules; all pinned in scripts/web-deps/package-lock.json) with `npm ci` and copies the module
# files the page loads into web/vendor/three/ (git-ignored), which rust-embed then embeds with the rest of web/.
# Only the files the page imports are copied, so the binary carries ~0.8 MB of three.js, not the package's 30 MB.
# Idempotent: nothing is reinstalled when the vendored copy was made from this very lock file (the stamp is the
# whole lock's hash, so a change to any pinned package reinstalls) and the type checker is installed.
set -euo pipefail

root="$(cd "$(dirname "$0")/.." && pwd)"
deps="$root/scripts/web-deps"
vendor="$root/web/vendor/three"
stamp="$vendor/.lock-sha256"

if ! command -v npm >/dev/null; then
    # Debian 12's own Node.js (18) runs npm and the generator alike; a newer Node from elsewhere ships its own npm.
    echo "web-deps: installing nodejs npm"
    sudo=""
    [[ $(id -u) -ne 0 ]] && sudo="sudo"
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends nodejs npm
fi

want="$(sha256sum "$deps/package-lock.json" | cut -d' ' -f1)"
if [[ -f "$stamp" && "$(cat "$stamp")" == "$want" && -x "$deps/node_modules/.bin/tsc" ]]; then
    echo "web-deps: three.js already in web/vendor, tsc in scripts/web-deps"
    exit 0
fi

echo "web-deps: npm ci (three.js, typescript)"
(cd "$deps" && npm ci --no-audit --no-fund --silent)

src="$deps/node_modules/three"
rm -rf "$vendor"
mkdir -p "$vendor/addons/loaders" "$vendor/addons/utils"
# three.module.min.js imports ./three.core.min.js; the loader imports 'three' (the page's import map) and
# ../utils/BufferGeometryUtils.js, so the addons keep their relative layout.
cp "$src/build/three.module.min.js" "$src/build/three.core.min.js" "$vendor/"
cp "$src/examples/jsm/loaders/GLTFLoader.js" "$vendor/addons/loaders/"
cp "$src/examples/jsm/utils/BufferGeometryUtils.js" "$vendor/addons/utils/"
cp "$src/LICENSE" "$vendor/LICENSE"
echo "$want" > "$stamp"
echo "web-deps: three.js $(node -p "require('$src/package.json').version" 2>/dev/null || echo '?') in web/vendor/three"
