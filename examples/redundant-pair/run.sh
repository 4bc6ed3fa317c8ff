#!/usr/bin/env bash
# A redundant pair of the default plant on this machine, in one command: an etcd, member a and member b.
#
#   examples/redundant-pair/run.sh          # Ctrl-C stops all three
#
# a serves the HMI on http://127.0.0.1:8080/ and OPC UA on port 4840, b on 8081 and 4841. Open both
# HMIs, then kill the active (the command is printed) and watch the other take over in about a
# second, from the same state; start it again with the printed command: it comes back as the standby.
# Everything it makes stays in examples/redundant-pair/work/ (delete it to start afresh).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
"$repo/scripts/bootstrap.sh"
python="$repo/.venv/bin/python"
if ! "$python" -c "import aetcd, msgpack" 2>/dev/null; then
  echo "installing the redundancy extra (aetcd, msgpack)" >&2
  "$python" -m pip install --quiet --disable-pip-version-check -e "$repo[redundancy]"
fi
command -v etcd >/dev/null 2>&1 || "$repo/scripts/apt-install.sh" etcd-server || { echo "needs etcd: apt-get install etcd-server" >&2; exit 1; }
work="$here/work"
mkdir -p "$work"
[ -f "$work/pair/a.crt" ] || "$python" -m softplc redundancy keys "$work/pair" >/dev/null
# The default plant, with its file references pointing back at the repository, and a pair.
sed -E 's#(^|[ "])(robots|hmi)/#\1../../../\2/#g' "$repo/tagdb.yaml" > "$work/tagdb.yaml"
cat >> "$work/tagdb.yaml" <<'YAML'

redundancy:                      # added by examples/redundant-pair/run.sh (docs/redundancy.md)
  preferred: a
  members:
    a: {sync: "127.0.0.1:7101", certificate: pair/a.crt, key: pair/a.key, opcua: "opc.tcp://127.0.0.1:4840/softplc/", hmi: "http://127.0.0.1:8080/"}
    b: {sync: "127.0.0.1:7102", certificate: pair/b.crt, key: pair/b.key, opcua: "opc.tcp://127.0.0.1:4841/softplc/", hmi: "http://127.0.0.1:8081/"}
  coordinator: {endpoints: ["127.0.0.1:23790"], lease: 1s}
YAML
pids=()
cleanup() { for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done; wait 2>/dev/null || true; }
trap cleanup EXIT INT TERM
# One etcd node, tuned for a 1 s lease (docs/redundancy.md: three nodes for a plant).
etcd --name pair --data-dir "$work/etcd" --listen-client-urls http://127.0.0.1:23790 --advertise-client-urls http://127.0.0.1:23790 \
     --listen-peer-urls http://127.0.0.1:23800 --initial-advertise-peer-urls http://127.0.0.1:23800 \
     --initial-cluster pair=http://127.0.0.1:23800 --heartbeat-interval 50 --election-timeout 500 --log-level warn \
     >"$work/etcd.log" 2>&1 &
pids+=($!)
export PYTHONPATH="$repo${PYTHONPATH:+:$PYTHONPATH}"
member() {  # NAME OPCUA_PORT MODBUS_PORT HMI_PORT
  echo "$python -m softplc run $work/tagdb.yaml --redundancy-member $1 --state-dir $work/state-$1 --no-status" \
       "--opcua-endpoint opc.tcp://127.0.0.1:$2/softplc/ --modbus-port $3 --hmi-port $4"
}
start() {  # NAME OPCUA_PORT MODBUS_PORT HMI_PORT
  $(member "$@") >>"$work/$1.log" 2>&1 &
  pids+=($!)
  echo "$!" > "$work/$1.pid"
}
start a 4840 5020 8080
start b 4841 5021 8081
cat <<TEXT
etcd on 127.0.0.1:23790, member a (HMI http://127.0.0.1:8080/, OPC UA :4840), member b (HMI http://127.0.0.1:8081/, OPC UA :4841)
logs in $work/{a,b,etcd}.log; which member is active:
  $python -m softplc redundancy status --endpoint opc.tcp://127.0.0.1:4840/softplc/,opc.tcp://127.0.0.1:4841/softplc/
kill the active (say a):    kill -9 \$(cat $work/a.pid)
start it again (standby):   $(member a 4840 5020 8080) &
Ctrl-C stops everything.
TEXT
wait "${pids[0]}"
