#!/usr/bin/env bash
# robocal sweeps on a real Slurm cluster (issues 15 and 27, item 7): the tested recipe of docs/sweep.md.
#
# Starts a one-node Slurm cluster on this machine (munged, slurmctld and slurmd on 127.0.0.1, run
# directly: no systemd; every file in one temporary folder), submits two `robocal sweep`s, a kinematic
# one and a `--score diagnose` power study, each as a job array of 4 shards (`--shard K/4`), then
# `robocal sweep-merge` as a job that depends on the array (`--dependency=afterok`), waits for both,
# and compares every file the merge writes (table, plot, parameter table, power table) with a
# one-machine run of the same sweep: they must be identical bytes. Daemons and files are removed on
# exit, whatever happens.
#
#   ./scripts/slurm_check.sh                 uses $ROBOCAL, else builds and uses target/debug/robocal
#   ROBOCAL=path/to/robocal ./scripts/...    the binary to test
#
# Needs Slurm (Debian: slurm-wlm, munge): installed with apt-get when missing and running as root.
# Works without stdin and with CI=true. Exit 0: identical bytes; 1: anything else, with the Slurm logs.
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD
start=$(date +%s)

say() { echo "slurm_check: $*" >&2; }
die() { say "FAILED: $*"; exit 1; }

# ---- Slurm itself --------------------------------------------------------------------------------
need=(munged munge slurmctld slurmd sbatch squeue scontrol sinfo)
missing() { for t in "${need[@]}"; do command -v "$t" >/dev/null || return 0; done; return 1; }
if missing; then
  [ "$(id -u)" = 0 ] || die "Slurm is not installed (apt-get install slurm-wlm munge, as root)"
  say "installing slurm-wlm and munge (Debian packages)"
  export DEBIAN_FRONTEND=noninteractive
  if ! apt-get install -y -qq --no-install-recommends slurm-wlm munge </dev/null >/dev/null 2>&1; then
    apt-get update -qq </dev/null >/dev/null
    apt-get install -y -qq --no-install-recommends slurm-wlm munge </dev/null >/dev/null
  fi
  missing && die "slurm-wlm and munge installed, but a tool is still missing"
fi
slurm_version=$(slurmctld -V)

# ---- the binary ----------------------------------------------------------------------------------
if [ -z "${ROBOCAL:-}" ]; then
  cargo build --quiet --bin robocal
  ROBOCAL=$repo/target/debug/robocal
fi
ROBOCAL=$(cd "$(dirname "$ROBOCAL")" && pwd)/$(basename "$ROBOCAL")
[ -x "$ROBOCAL" ] || die "$ROBOCAL is not an executable"

# ---- one folder for everything, removed on exit ---------------------------------------------------
work=$(mktemp -d "${TMPDIR:-/tmp}/robocal-slurm.XXXXXX")
chmod 755 "$work" # munged wants the socket's folder searchable by all
mkdir -p "$work/state" "$work/spool" "$work/logs"
status=1
cleanup() {
  local rc=$?
  set +e # a failing write (closed stderr) must not stop the cleanup
  trap - EXIT INT TERM HUP
  if [ "$status" != 0 ]; then
    say "exit $rc; the Slurm logs:"
    for f in "$work"/slurmctld.log "$work"/slurmd.log "$work"/munged.log "$work"/logs/*; do
      [ -f "$f" ] || continue
      echo "---- ${f#"$work"/} (last 40 lines)" >&2
      tail -n 40 "$f" >&2
    done
    [ -n "${SLURM_CONF:-}" ] && command -v squeue >/dev/null && squeue 2>/dev/null >&2 || true
  fi
  # Stop the daemons this script started (by the pids in their pid files) and wait for them to go.
  local pids=() d pid
  for d in slurmd slurmctld munged; do
    [ -s "$work/$d.pid" ] || continue
    pid=$(cat "$work/$d.pid")
    kill "$pid" 2>/dev/null && pids+=("$pid")
  done
  for pid in "${pids[@]}"; do
    for _ in $(seq 100); do kill -0 "$pid" 2>/dev/null || break; sleep 0.05; done
    kill -9 "$pid" 2>/dev/null || true
  done
  rm -rf "$work"
  exit "$rc"
}
trap cleanup EXIT
trap 'exit 1' INT TERM HUP
trap '' PIPE # a closed stderr (| head) must not kill the script before its cleanup

# Two free TCP ports on 127.0.0.1 for slurmctld and slurmd (a cluster already on this machine keeps
# its own).
read -r ctld_port slurmd_port < <(python3 -c '
import socket
s = [socket.socket() for _ in range(2)]
for x in s: x.bind(("127.0.0.1", 0))
print(*(x.getsockname()[1] for x in s))')

# ---- munge --------------------------------------------------------------------------------------
head -c 1024 /dev/urandom >"$work/munge.key"
chmod 600 "$work/munge.key"
munged --force --socket="$work/munge.sock" --key-file="$work/munge.key" \
  --pid-file="$work/munged.pid" --log-file="$work/munged.log" --seed-file="$work/munged.seed" \
  </dev/null || die "munged did not start"
munge -n -S "$work/munge.sock" </dev/null | unmunge -S "$work/munge.sock" >/dev/null \
  || die "munge cannot encode and decode a credential"

# ---- Slurm: one node, this machine --------------------------------------------------------------
# No systemd and no cgroups in a container: processes are tracked through /proc (proctrack/linuxproc),
# tasks are not bound (task/none), no accounting database.
host=$(hostname)
cpus=$(nproc)
export SLURM_CONF=$work/slurm.conf
cat >"$SLURM_CONF" <<EOF
ClusterName=robocal-check
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=$(id -un)
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$work/munge.sock
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
MpiDefault=none
ReturnToService=2
MinJobAge=600
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=check Nodes=$host Default=YES MaxTime=30 State=UP
EOF
slurmctld -c </dev/null || die "slurmctld did not start" # -c: a new cluster, no saved state
slurmd </dev/null || die "slurmd did not start"
for _ in $(seq 100); do
  state=$(sinfo -h -n "$host" -o %T 2>/dev/null || true)
  [ "$state" = idle ] && break
  sleep 0.2
done
[ "$state" = idle ] || die "the node is '$state', not idle, after 20 s"
say "$slurm_version: one node ($host, $cpus CPUs) up in $(($(date +%s) - start)) s"

# ---- the studies: each a job array of 4 shards, then the merge -----------------------------------
shards=4
jobs_ok() { scontrol -o show job "$1" 2>/dev/null | grep -c 'JobState=COMPLETED .*ExitCode=0:0' || true; }

# study NAME ARGS…: `robocal sweep ARGS` as a Slurm job array of $shards shards and a merge job that
# waits for it (afterok), then on this machine alone: every file the merge writes must be the bytes
# of the one-machine run's, and they must write the same files.
study() {
  local name=$1
  shift
  local sweep=(sweep "$@")
  local dir="$work/$name"
  mkdir -p "$dir/parts"
  cat >"$dir/sweep.sbatch" <<SBATCH
#!/bin/bash
#SBATCH --job-name=robocal-$name
#SBATCH --array=0-$((shards - 1))
#SBATCH --cpus-per-task=1
#SBATCH --time=10
#SBATCH --output=$work/logs/${name}_%A_%a.out
set -euo pipefail
export RAYON_NUM_THREADS=\$SLURM_CPUS_PER_TASK
"$ROBOCAL" ${sweep[*]} --shard "\$SLURM_ARRAY_TASK_ID/$shards" --out "$dir/parts/part\$SLURM_ARRAY_TASK_ID.parquet"
SBATCH
  cat >"$dir/merge.sbatch" <<SBATCH
#!/bin/bash
#SBATCH --job-name=robocal-$name-merge
#SBATCH --cpus-per-task=1
#SBATCH --time=10
#SBATCH --output=$work/logs/${name}_merge_%j.out
set -euo pipefail
"$ROBOCAL" sweep-merge --out "$dir/study.parquet" "$dir"/parts/part*.parquet
SBATCH
  local array merge tasks
  array=$(sbatch --parsable "$dir/sweep.sbatch" </dev/null) || die "$name: sbatch refused the array job"
  array=${array%%;*}
  say "$name: submitted the array job $array ($shards shards); the merge waits for it (afterok)"
  timeout 600 sbatch --parsable --wait --dependency="afterok:$array" --kill-on-invalid-dep=yes \
    "$dir/merge.sbatch" </dev/null >"$dir/merge.jobid" \
    || die "$name: the merge job did not complete (array $array failed, or the wait timed out)"
  # Every array task and the merge must have completed with exit code 0 (sbatch --wait alone does
  # not tell a merge cancelled for a failed dependency from one that ran).
  merge=$(cut -d';' -f1 "$dir/merge.jobid")
  tasks=$(jobs_ok "$array")
  [ "$tasks" = "$shards" ] || die "$name: $tasks of $shards array tasks completed with exit code 0"
  [ "$(jobs_ok "$merge")" = 1 ] \
    || die "$name: the merge job $merge did not complete: $(scontrol -o show job "$merge" | grep -o 'JobState=[^ ]*')"
  [ -s "$dir/study.parquet" ] && [ -s "$dir/study.svg" ] || die "$name: the merge wrote no study.parquet/.svg"
  # The same sweep on one machine, and the comparison of every file the merge wrote.
  "$ROBOCAL" "${sweep[@]}" --out "$dir/single.parquet" 2>"$work/logs/${name}_single.err" </dev/null \
    || die "$name: the one-machine sweep failed"
  local merged single f
  merged=$(cd "$dir" && ls study.* | sed 's/^study\.//' | tr '\n' ' ')
  single=$(cd "$dir" && ls single.* | sed 's/^single\.//' | tr '\n' ' ')
  [ "$merged" = "$single" ] || die "$name: the merge wrote $merged, the one-machine run $single"
  for f in $merged; do
    cmp "$dir/study.$f" "$dir/single.$f" || die "$name: the merged study.$f differs from the one-machine run's"
  done
  say "$name: OK, $shards Slurm array tasks + merge give the bytes of the one-machine run" \
    "(study.{${merged% }} identical; study.parquet sha256 $(sha256sum "$dir/study.parquet" | cut -c1-16)…)"
}

# Small on purpose: the point is the cluster path, not the studies. A kinematic sweep (12
# generate-calibrate-score runs) and a diagnose power study (8 runs; its power table too).
study kinematic --scenario "$repo/scenarios/iiwa7_kinematic.toml" --noise 0.5,1 --poses 20,40 --reps 3 --seed 11
study diagnose --scenario "$repo/scenarios/iiwa7_backlash.toml" --score diagnose --noise 1 --poses 60 \
  --magnitude 0,1 --magnitude-of gear_backlash --reps 4 --seed 12
status=0
say "OK: both studies on Slurm give the bytes of the one-machine runs; $(($(date +%s) - start)) s in all"
