#!/bin/sh
# make test-ui: the web UI's tests in a real browser (tests/ui/ui_test.mjs, and
# tests/ui/site_test.mjs for the Site page with a broker and a second host).
# Installs what they need when it is missing: Debian's chromium (apt), and
# through tests/npm_ci.sh Node.js 20 or later and playwright-core at the
# version tests/ui/package-lock.json pins.
# When chromium or a Node.js new enough cannot be installed on this machine
# the suite cannot run:
#   - with CI=true in the environment that is a failure (exit 1, the reason
#     printed): a CI run must not pass a suite it did not run;
#   - elsewhere it is skipped (exit 0) with a banner, and the reason is
#     appended to the file $VMAC_SKIP_FILE when that is set (make test
#     lists every skipped suite there at its end).
#
#   tests/ui/run.sh BIN_DIR OUT_DIR
set -eu
bin=$1
out=$2
here=$(cd "$(dirname "$0")" && pwd)
sudo=""
[ "$(id -u)" = 0 ] || sudo=sudo

install() {
	$sudo apt-get update -qq && $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "$@"
}

# The suite cannot run, for reason $1: fail under CI, else skip loudly.
cannot_run() {
	if [ "${CI:-}" = true ]; then
		echo "test-ui: FAILED: the web UI's tests cannot run: $1" >&2
		echo "test-ui: (CI=true: a suite that cannot run is a failure, not a skip)" >&2
		exit 1
	fi
	echo "################################################################################"
	echo "## test-ui: SKIPPED: the web UI's tests did not run"
	echo "## $1"
	echo "################################################################################"
	if [ -n "${VMAC_SKIP_FILE:-}" ]; then
		echo "test-ui: $1" >>"$VMAC_SKIP_FILE"
	fi
	exit 0
}

if [ ! -x /usr/bin/chromium ]; then
	echo "test-ui: installing chromium"
	install chromium || true
fi
if [ ! -x /usr/bin/chromium ]; then
	cannot_run "Debian's chromium cannot be installed on this machine"
fi
# Node.js 20 or later and playwright-core at the version package-lock.json pins.
if ! why=$("$here/../npm_ci.sh" "$here" 20 2>&1 >/dev/null); then
	cannot_run "$why"
fi
echo "== the web UI in headless chromium (screenshots in $out)"
rm -f "$out"/*.log # each program's log is appended to as it runs: this run's only
failed=0
node "$here/ui_test.mjs" --bin "$bin" --out "$out" || failed=1
echo "== the Site page: two hosts on one MQTT broker (tests/ui/site_test.mjs)"
node "$here/site_test.mjs" --bin "$bin" --out "$out" || failed=1
exit $failed
