#!/bin/sh
# make test-ui: the web UI's tests in a real browser (tests/ui/ui_test.mjs).
# Installs what they need when it is missing: Debian's chromium (apt) and,
# when there is no Node.js 20 or later, Debian's nodejs and npm; then
# playwright-core from npm at the version tests/ui/package-lock.json pins.
# When chromium or a Node.js new enough cannot be installed on this machine,
# says so and skips (exit 0): the rest of make test does not depend on them.
#
#   tests/ui/run.sh BIN_DIR OUT_DIR
set -eu
bin=$1
out=$2
here=$(cd "$(dirname "$0")" && pwd)
sudo=""
[ "$(id -u)" = 0 ] || sudo=sudo

node_ok() {
	command -v node >/dev/null && command -v npm >/dev/null &&
		[ "$(node -p 'process.versions.node.split(".")[0]')" -ge 20 ]
}

install() {
	$sudo apt-get update -qq && $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "$@"
}

if [ ! -x /usr/bin/chromium ]; then
	echo "test-ui: installing chromium"
	install chromium || true
fi
if ! node_ok; then
	echo "test-ui: installing nodejs and npm"
	install nodejs npm || true
fi
if [ ! -x /usr/bin/chromium ]; then
	echo "test-ui: SKIPPED: Debian's chromium cannot be installed on this machine"
	exit 0
fi
if ! node_ok; then
	echo "test-ui: SKIPPED: playwright-core needs Node.js 20 or later, and this machine has $(node --version 2>/dev/null || echo none)"
	exit 0
fi
(cd "$here" && npm ci --no-audit --no-fund --loglevel=error)
echo "== the web UI in headless chromium (screenshots in $out)"
exec node "$here/ui_test.mjs" --bin "$bin" --out "$out"
