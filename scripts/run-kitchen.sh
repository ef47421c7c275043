#!/usr/bin/env bash
# The demo kitchen: vmacd plus three mock boards (washer, dishwasher, lights)
# in the foreground. Ctrl-C stops everything; every board ends with its
# outputs off. Usage: scripts/run-kitchen.sh [BIN_DIR] (default build/bin).
# Environment: VMAC_BUS (GROUP:PORT), VMAC_HTTP (ADDR:PORT).
set -u
bin=${1:-build/bin}
bus=${VMAC_BUS:-239.255.86.77:5870}
http=${VMAC_HTTP:-127.0.0.1:8080}
pids=()

# Ctrl-C in the terminal reaches every process of the kitchen at once, so
# then we only wait; a TERM (or a process ending) must be passed on.
stop() {
	trap - INT TERM
	echo
	echo "run-kitchen: stopping the host and the boards"
	[ "$1" = INT ] || kill -TERM "${pids[@]}" 2>/dev/null
	wait
	echo "run-kitchen: stopped"
	exit 0
}
trap 'stop INT' INT
trap 'stop TERM' TERM
# Background jobs get /dev/null as stdin unless told otherwise; the lights
# board reads this terminal, so keep a handle on it.
exec 3<&0

"$bin/vmacd" --bus "$bus" --http "$http" &
pids+=($!)
"$bin/vmac-board" --plant washer --name washer-1 --bus "$bus" --quiet </dev/null &
pids+=($!)
"$bin/vmac-board" --plant dishwasher --name dishwasher-1 --bus "$bus" --quiet </dev/null &
pids+=($!)
# The lights board reads operator actions from this terminal.
"$bin/vmac-board" --plant lights --name lights-1 --bus "$bus" --quiet --commands <&3 &
pids+=($!)

cat <<EOT

The demo kitchen is running.
  status page:   http://$http/api/status
  in a shell:    $bin/vmac status --http $http
  flip a wall switch (type here, then Enter):   lights-1 toggle1 1
  Ctrl-C stops the host and the boards (all outputs off).

EOT
wait -n "${pids[@]}"
echo "run-kitchen: a process ended on its own; stopping the rest"
stop TERM
