#!/usr/bin/env bash
# A farm bake on a one-node Slurm cluster on this machine, checked against a
# one-process bake (docs/farm.md). As root on Debian 12:
#   1. installs slurm-wlm and munge when missing (apt-get update first);
#   2. starts munged, slurmctld and slurmd with a cluster of one node, this
#      host with 2 CPUs (../shared/docs/slurm-one-node.md); the config, state
#      and logs live in the work folder (SLURM_CONF), /etc/slurm is not touched;
#   3. writes the demo scene, submits `lapflow farm slurm` of it and waits;
#   4. checks that every frame's colour and displacement EXR, AOV, OBJ and MTL
#      have the sha256 digest of a one-process `lapflow bake` of the same scene;
#   5. re-submits the same farm command (every job finds its work done and no
#      frame is rewritten), deletes frame 5's files and re-runs its task alone
#      (sbatch --array=I render.S-E.sh, as docs/farm.md says), and checks the
#      digests again;
#   6. stops the daemons it started, by process id, whatever happens.
# Usage: bash scripts/slurm-test.sh [BUILD_DIR]   (default build; the binary
# must be built). FRAMES (8), CHUNK (3), ATLAS (256) and WORK (a new folder
# under /tmp, removed after a pass unless KEEP=1) change the run.
set -euo pipefail
cd "$(dirname "$0")/.."
lapflow=$(realpath "${1:-build}/lapflow")
frames=${FRAMES:-8}
chunk=${CHUNK:-3}
atlas=${ATLAS:-256}
[ "$frames" -ge 5 ] || { echo "slurm-test: FRAMES must be at least 5 (frame 5 is re-run)" >&2; exit 2; }
[ -x "$lapflow" ] || { echo "slurm-test: $lapflow is not built" >&2; exit 2; }
[ "$(id -u)" = 0 ] || { echo "slurm-test: needs root (it installs packages and runs the Slurm daemons)" >&2; exit 2; }
t0=$(date +%s)
say() { echo "slurm-test [$(( $(date +%s) - t0 ))s]: $*"; }

# ---- 1. packages -------------------------------------------------------------
if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null || ! command -v munged >/dev/null; then
  say "installing slurm-wlm and munge"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge >/dev/null
fi

# ---- 2. the cluster --------------------------------------------------------------
if pgrep -x slurmctld >/dev/null || pgrep -x slurmd >/dev/null; then
  echo "slurm-test: a Slurm daemon already runs on this machine (pgrep -x slurmctld / slurmd); stop it first" >&2
  exit 2
fi
work=${WORK:-$(mktemp -d /tmp/lapflow-slurm.XXXXXX)}
mkdir -p "$work"/slurm/{state,spool,log}
pids=()  # the daemons this script started
cleanup() {
  local rc=$?
  # Jobs first (a job step outlives a killed slurmd), then the daemons.
  if [ ${#pids[@]} -gt 0 ]; then
    jobs=$(squeue -h -o %i 2>/dev/null || true)
    [ -z "$jobs" ] || scancel $jobs 2>/dev/null || true
    for _ in 1 2 3 4 5; do [ -z "$(squeue -h -o %i 2>/dev/null || true)" ] && break; sleep 1; done
    for ((i = ${#pids[@]} - 1; i >= 0; i--)); do kill "${pids[$i]}" 2>/dev/null || true; done
    for p in "${pids[@]}"; do
      for _ in $(seq 50); do kill -0 "$p" 2>/dev/null || break; sleep 0.1; done
    done
  fi
  if [ "$rc" = 0 ] && [ "${KEEP:-0}" != 1 ] && [ -z "${WORK:-}" ]; then rm -rf "$work"; else echo "slurm-test: files kept in $work"; fi
  return "$rc"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

# munge: the package ships /etc/munge/munge.key; a munged already running is used as it is.
if ! munge -n </dev/null 2>/dev/null | unmunge >/dev/null 2>&1; then
  mkdir -p /run/munge && chown munge:munge /run/munge
  setpriv --reuid=munge --regid=munge --init-groups /usr/sbin/munged --foreground >"$work/slurm/log/munged.log" 2>&1 &
  pids+=($!)
  for _ in $(seq 50); do munge -n </dev/null 2>/dev/null | unmunge >/dev/null 2>&1 && break; sleep 0.1; done
  munge -n </dev/null | unmunge >/dev/null || { echo "slurm-test: munged does not answer" >&2; exit 1; }
fi

host=$(hostname)
memory=$(awk '/MemTotal/ { printf "%d", $2 / 1024 * 0.8 }' /proc/meminfo)
export SLURM_CONF=$work/slurm/slurm.conf
cat >"$SLURM_CONF" <<EOF
ClusterName=lapflowtest
SlurmctldHost=$host
SlurmUser=root
AuthType=auth/munge
StateSaveLocation=$work/slurm/state
SlurmdSpoolDir=$work/slurm/spool
SlurmctldPidFile=$work/slurm/slurmctld.pid
SlurmdPidFile=$work/slurm/slurmd.pid
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
SlurmctldLogFile=$work/slurm/log/slurmctld.log
SlurmdLogFile=$work/slurm/log/slurmd.log
JobCompType=jobcomp/none
NodeName=$host CPUs=2 RealMemory=$memory State=UNKNOWN
PartitionName=main Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
/usr/sbin/slurmctld -D -i >"$work/slurm/log/slurmctld.out" 2>&1 &
pids+=($!)
sleep 2
/usr/sbin/slurmd -D >"$work/slurm/log/slurmd.out" 2>&1 &
pids+=($!)
for _ in $(seq 60); do
  [ "$(sinfo -h -o %T 2>/dev/null)" = idle ] && break
  sleep 1
done
[ "$(sinfo -h -o %T)" = idle ] || { echo "slurm-test: the node is not idle: $(sinfo -h)" >&2; exit 1; }
say "cluster up: $(sinfo -h -o '%P %a %D node %N, %c CPUs, %T')"

# ---- 3. the farm bake ------------------------------------------------------------
"$lapflow" demo --out "$work/demo" --frames "$frames" --resolution 64 --no-bake --no-preview --quiet
cat >"$work/shot.toml" <<EOF
mesh = "demo/demo.%04d.ply"
exemplar = "pebbles"
radius = 0.05
resolution = $atlas
aov = true
EOF
wait_for_jobs() {
  local deadline=$(( $(date +%s) + ${1:-1800} ))
  while [ -n "$(squeue -h -o %i)" ]; do
    [ "$(date +%s)" -lt "$deadline" ] || { echo "slurm-test: jobs still queued after the deadline:" >&2; squeue >&2; exit 1; }
    sleep 2
  done
}
# The farm's command, from the work folder: the scene file's paths are relative to it.
farm=("$lapflow" farm slurm shot.toml --threads 1 --out farm --chunk "$chunk")
cd "$work"
farm_start=$(date +%s)
"${farm[@]}" >"$work/submit.txt"
say "submitted $frames frames in chunks of $chunk:"
sed 's/^/  /' "$work/submit.txt"
wait_for_jobs
farm_seconds=$(( $(date +%s) - farm_start ))
say "farm bake done in ${farm_seconds}s"
"$lapflow" farm status farm | tee "$work/status.txt" | sed 's/^/  /'
failed=()
for log in farm/farm/logs/*.log; do grep -qx "lapflow farm: exit 0" "$log" || failed+=("$log"); done
if [ ${#failed[@]} -gt 0 ] || ! grep -qx "$frames frames: $frames rendered, .*" "$work/status.txt"; then
  echo "slurm-test: FAIL: not every frame was rendered, or a job did not end with exit 0:" >&2
  for log in "${failed[@]}"; do echo "== $log" >&2; tail -5 "$log" >&2; done
  exit 1
fi

# ---- 4. the same bytes as one process ------------------------------------------
bake_start=$(date +%s)
"$lapflow" bake shot.toml --threads 1 --out ref --quiet
bake_seconds=$(( $(date +%s) - bake_start ))
say "one-process bake done in ${bake_seconds}s"
digests() {  # digests DIR: one line per frame file, sorted
  (cd "$1" && sha256sum demo.[0-9]*.obj demo.[0-9]*.mtl demo.color.*.exr demo.disp.*.exr demo.aov.*.exr | sort -k2)
}
check_same() {
  local n
  n=$(digests ref | wc -l)
  [ "$n" = $((5 * frames)) ] || { echo "slurm-test: the one-process bake wrote $n frame files, not $((5 * frames))" >&2; exit 1; }
  if ! diff <(digests ref) <(digests farm) >"$work/digests.diff"; then
    echo "slurm-test: FAIL ($1): the farm's files differ from the one-process bake's:" >&2
    cat "$work/digests.diff" >&2
    exit 1
  fi
  say "$1: all $n frame files (OBJ, MTL, colour, displacement, AOV) have the one-process bake's sha256"
}
check_same "farm bake"

# ---- 5. re-submitted, and one task re-run alone ------------------------------------
before=$(stat -c '%n %Y' farm/demo.[0-9]*.obj | sort)
resubmit_start=$(date +%s)
"${farm[@]}" >/dev/null
wait_for_jobs
after=$(stat -c '%n %Y' farm/demo.[0-9]*.obj | sort)
[ "$before" = "$after" ] || { echo "slurm-test: a re-submitted farm rewrote finished frames" >&2; exit 1; }
say "re-submitted farm: every job found its work done ($(( $(date +%s) - resubmit_start ))s), no frame rewritten"
check_same "re-submitted farm"
# Frame 5's task "failed": its files are gone; the command the farm printed brings it back.
rm farm/demo.0005.obj farm/demo.0005.mtl farm/demo.color.0005.exr farm/demo.disp.0005.exr farm/demo.aov.0005.exr
# The command the farm prints for it: task 5 - FIRST of the array of the chunk FIRST-LAST holding frame 5.
first=$(( 1 + (5 - 1) / chunk * chunk ))
last=$(( first + chunk - 1 < frames ? first + chunk - 1 : frames ))
script=$work/farm/farm/$(printf 'render.%04d-%04d.sh' "$first" "$last")
sbatch --array=$((5 - first)) "$script" >/dev/null
wait_for_jobs
check_same "frame 5 re-run alone (sbatch --array=$((5 - first)) $script)"

say "PASS: farm bake of $frames frames (chunks of $chunk, atlas ${atlas}², 2 CPUs) in ${farm_seconds}s, one-process bake ${bake_seconds}s; wall time $(( $(date +%s) - t0 ))s in all"
