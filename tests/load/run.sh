#!/usr/bin/env bash
# make test, RUNS times in a row (default 3), beside issue #36's load:
# stress-ng --cpu 2 --vm 1 --vm-bytes 1G --hdd 1 (Debian's stress-ng) and a
# second clone built again and again with make -j4 (docs/TESTING.md,
# "Under load"). Each run is CI=true make test in a clean clone of this
# repository's HEAD; logs and a summary go to build/load/. Exits 1 when a
# run failed. Usage: tests/load/run.sh [RUNS]
set -u
runs=${1:-3}
root=$(git rev-parse --show-toplevel) || exit 2
out=$root/build/load
mkdir -p "$out"
if ! command -v stress-ng >/dev/null; then
	apt-get install -y -qq stress-ng >/dev/null || { echo "tests/load: cannot install stress-ng" >&2; exit 2; }
fi
work=$(mktemp -d /tmp/vmac-load.XXXXXX)
git clone -q "$root" "$work/suite" && git clone -q "$root" "$work/churn" || exit 2

# The load, each in a process group of its own so that it stops whole.
setsid bash -c 'cd "$0" && exec stress-ng --cpu 2 --vm 1 --vm-bytes 1G --hdd 1 --timeout 0' "$work" \
	>"$out/stress.log" 2>&1 &
stress=$!
setsid bash -c 'cd "$0" && while :; do make clean >/dev/null 2>&1; make -j4 all >/dev/null 2>&1; done' \
	"$work/churn" &
churn=$!
stop() {
	kill -- -"$stress" -"$churn" 2>/dev/null
	wait 2>/dev/null
	rm -rf "$work"
}
trap stop EXIT INT TERM

failed=0
: >"$out/summary"
for i in $(seq 1 "$runs"); do
	t0=$(date +%s)
	(cd "$work/suite" && CI=true make test) >"$out/run-$i.log" 2>&1
	rc=$?
	line="run $i of $runs: $( [ $rc = 0 ] && echo passed || echo FAILED) in $(( $(date +%s) - t0 )) s, load average $(cut -d' ' -f1-3 /proc/loadavg)"
	echo "$line" | tee -a "$out/summary"
	[ $rc = 0 ] || { failed=1; grep -E '^FAIL|failed|Error' "$out/run-$i.log" | head -20 | tee -a "$out/summary"; }
done
exit $failed
