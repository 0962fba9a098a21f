#!/usr/bin/env bash
# Data-parallel training: starts N ranks of build/bin/hsd_train on this host
# with torchrun's environment (WORLD_SIZE, RANK, LOCAL_RANK, LOCAL_WORLD_SIZE,
# MASTER_ADDR, MASTER_PORT) and waits for them. The first rank that fails
# makes this script stop the others (after a short grace period in which they
# report the failure themselves) and exit with that rank's code.
#
#   scripts/launch_distributed.sh [--nproc N] [--nnodes M --node-rank K --master-addr HOST]
#                                 [--master-port P] [--grace S] -- HSD_TRAIN_ARGS...
#
# One host, 2 ranks (each gets cores / 2 threads when the config says threads = 0):
#   scripts/launch_distributed.sh --nproc 2 -- --config configs/quick.json --out out/quick/dp
# Two hosts with 2 ranks each (run on both; data.root and --out may be local to each host;
# only global rank 0 writes):
#   host0$ scripts/launch_distributed.sh --nproc 2 --nnodes 2 --node-rank 0 --master-addr host0 --master-port 29500 -- ...
#   host1$ scripts/launch_distributed.sh --nproc 2 --nnodes 2 --node-rank 1 --master-addr host0 --master-port 29500 -- ...
set -uo pipefail
cd "$(dirname "$0")/.."

nproc=2 nnodes=1 node_rank=0 addr=127.0.0.1 port="" grace=10
bin="${HSD_TRAIN_BIN:-build/bin/hsd_train}"
die() { echo "launch_distributed: error: $*" >&2; exit 2; }
is_int() { [[ "$1" =~ ^[0-9]+$ ]]; }
while [ $# -gt 0 ]; do
  case "$1" in
    --nproc) is_int "${2:-}" && [ "$2" -ge 1 ] || die "--nproc needs a positive integer"; nproc=$2; shift 2 ;;
    --nnodes) is_int "${2:-}" && [ "$2" -ge 1 ] || die "--nnodes needs a positive integer"; nnodes=$2; shift 2 ;;
    --node-rank) is_int "${2:-}" || die "--node-rank needs an integer >= 0"; node_rank=$2; shift 2 ;;
    --master-addr) [ -n "${2:-}" ] || die "--master-addr needs a host"; addr=$2; shift 2 ;;
    --master-port) is_int "${2:-}" && [ "$2" -ge 1 ] && [ "$2" -le 65535 ] || die "--master-port needs a port in [1, 65535]"; port=$2; shift 2 ;;
    --grace) is_int "${2:-}" || die "--grace needs seconds"; grace=$2; shift 2 ;;
    --help|-h) sed -n '2,17p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    --) shift; break ;;
    *) die "unknown option '$1' (hsd_train's arguments go after --)" ;;
  esac
done
[ "$node_rank" -lt "$nnodes" ] || die "--node-rank $node_rank is not below --nnodes $nnodes"
[ -x "$bin" ] || die "$bin not found: build first (bash scripts/build.sh)"
if [ -z "$port" ]; then
  if [ "$nnodes" -gt 1 ]; then
    port=29500
  else  # one host: a free port, so several runs can share the machine
    for _ in $(seq 1 50); do
      port=$((20000 + RANDOM % 20000))
      (exec 3<>"/dev/tcp/127.0.0.1/$port") 2>/dev/null || break
    done
  fi
fi

world=$((nproc * nnodes))
pids=()
stop_all() {
  for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null; done
}
trap 'stop_all; exit 130' INT TERM
echo "launch_distributed: $nproc ranks on this host (node $node_rank of $nnodes, world $world), master $addr:$port" >&2
for ((l = 0; l < nproc; ++l)); do
  r=$((node_rank * nproc + l))
  if [ "$r" -eq 0 ]; then
    WORLD_SIZE=$world RANK=$r LOCAL_RANK=$l LOCAL_WORLD_SIZE=$nproc MASTER_ADDR=$addr MASTER_PORT=$port \
      "$bin" "$@" &
  else  # other ranks' lines are prefixed with their rank
    WORLD_SIZE=$world RANK=$r LOCAL_RANK=$l LOCAL_WORLD_SIZE=$nproc MASTER_ADDR=$addr MASTER_PORT=$port \
      "$bin" "$@" > >(sed -u "s/^/[rank $r] /") 2> >(sed -u "s/^/[rank $r] /" >&2) &
  fi
  pids+=($!)
done

# Wait for each rank; on the first failure give the rest `grace` seconds to
# notice (they exit with code 4 and say why), then stop them.
status=0
live=("${pids[@]}")
while [ "${#live[@]}" -gt 0 ]; do
  finished=""
  wait -n -p finished "${live[@]}"
  code=$?
  [ -n "$finished" ] || break  # nothing left to wait for
  next=()
  for p in "${live[@]}"; do [ "$p" != "$finished" ] && next+=("$p"); done
  live=("${next[@]+"${next[@]}"}")
  if [ "$code" -ne 0 ] && [ "$status" -eq 0 ]; then
    status=$code
    echo "launch_distributed: a rank exited with code $code; stopping the others in ${grace} s" >&2
    for ((t = 0; t < grace * 10; ++t)); do
      alive=0
      for p in "${live[@]+"${live[@]}"}"; do kill -0 "$p" 2>/dev/null && alive=1; done
      [ "$alive" -eq 0 ] && break
      sleep 0.1
    done
    stop_all
  fi
done
wait
exit "$status"
