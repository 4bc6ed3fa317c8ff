#!/usr/bin/env bash
# The VDA 5050 example in one command: the plant (with its embedded MQTT broker) and two of our simulated
# TurtleBots as VDA 5050 vehicles (softplc robot-agent --vda5050). Ctrl-C stops all three.
#   examples/vda5050/run.sh            then open http://127.0.0.1:8080/ ; `softplc vda5050 vehicles` lists the vehicles
# Arguments go to `softplc run` (real time only: the vehicles are separate processes on the wall clock).
set -euo pipefail
cd "$(dirname "$0")/../.."
[ -x .venv/bin/softplc ] || scripts/bootstrap.sh
softplc=.venv/bin/softplc
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"  # the plant's programs are the repository's programs/
broker=mqtt://127.0.0.1:1884
pids=()
stop() { kill "${pids[@]}" 2>/dev/null || true; wait 2>/dev/null || true; }
trap stop EXIT INT TERM
"$softplc" run examples/vda5050/tagdb.yaml "$@" &
pids+=($!)
sleep 1  # the vehicles connect once the embedded broker listens (they retry on their own)
for robot in r03 r04; do
  "$softplc" robot-agent --vda5050 "$broker" --robot "$robot" --robots examples/vda5050/robots.yaml \
    --map robots/maps/factory.yaml --state-interval 1 &
  pids+=($!)
done
wait "${pids[0]}"
