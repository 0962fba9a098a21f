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
# Two hosts with 2 ranks each (run on both). Only global rank 0 writes (to its --out); every
# host needs the dataset in data.root (a shared folder or a copy: only rank 0 generates one)
# and, for --resume, DIR/checkpoints/last.pt:
#   host0$ scripts/launch_distributed.sh --nproc 2 --nnodes 2 --node-rank 0 --master-addr host0 --master-port 29500 -- ...
#   host1$ scripts/launch_distributed.sh --nproc 2 --nnodes 2 --node-rank 1 --master-addr host0 --master-port 29500 -- ...
set -uo pipefail
# Relative paths in hsd_train's arguments stay relative to where this is run.
root="$(cd "$(dirname "$0")/.." && pwd)"

nproc=2 nnodes=1 node_rank=0 addr="" port="" grace=10
bin="${HSD_TRAIN_BIN:-$root/build/bin/hsd_train}"
die() { echo "launch_distributed: error: $*" >&2; exit 2; }
# wait -n -p (bash 5.1) tells which rank ended; older shells would miss failures.
if [ "${BASH_VERSINFO[0]}" -lt 5 ] || { [ "${BASH_VERSINFO[0]}" -eq 5 ] && [ "${BASH_VERSINFO[1]}" -lt 1 ]; }; then
  die "needs bash >= 5.1 (this is $BASH_VERSION)"
fi
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
if [ -z "$addr" ]; then
  [ "$nnodes" -eq 1 ] || die "--master-addr is required with --nnodes > 1 (the host of node 0)"
  addr=127.0.0.1
fi
[ -x "$bin" ] || die "$bin not found: build first (bash scripts/build.sh)"
if [ -z "$port" ]; then
  if [ "$nnodes" -gt 1 ]; then
    port=29500
  else  # one host: a free port below Linux's ephemeral range, so several runs can share the machine
    for _ in $(seq 1 50); do
      port=$((20000 + RANDOM % 12000))
      (exec 3<>"/dev/tcp/127.0.0.1/$port") 2>/dev/null || break
    done
  fi
fi

world=$((nproc * nnodes))
pids=()
# TERM to every rank still running, then KILL to any that ignore it for 5 s.
stop_all() {
  for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null; done
  for ((t = 0; t < 50; ++t)); do
    alive=0
    for p in "${pids[@]}"; do kill -0 "$p" 2>/dev/null && alive=1; done
    [ "$alive" -eq 0 ] && return
    sleep 0.1
  done
  for p in "${pids[@]}"; do kill -KILL "$p" 2>/dev/null; done
}
trap 'stop_all; exit 130' INT
trap 'stop_all; exit 143' TERM
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
  if [ -z "$finished" ]; then  # should not happen with bash >= 5.1: never report success blindly
    echo "launch_distributed: lost track of the ranks (wait returned $code)" >&2
    stop_all
    exit 1
  fi
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
