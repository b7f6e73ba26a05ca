#!/usr/bin/env bash
# The calibration Monte Carlo as a Slurm job array, on a single-node Slurm started here, and
# the check that its merged summary equals the unsharded run's.
#
#   scripts/slurm_campaign.sh [N=4] [SHARDS=2] [WORK=/tmp/slurm-campaign] [SCENARIO=gro-early-mission]
#
# 1. Installs what is missing from Debian's packages (slurm-wlm, munge) and builds
#    calibration-mc (release).
# 2. Starts munged, slurmctld and slurmd with a minimal configuration in WORK/etc (one node,
#    this machine, all its CPUs; state and logs in WORK), as root.
# 3. Flies the campaign unsharded (timed), then submits it as a job array of SHARDS tasks
#    (`sbatch --array=0-(SHARDS-1) --wait`, each task
#    `calibration-mc --shard $SLURM_ARRAY_TASK_ID/SHARDS --shard-out WORK/shards`), timed from
#    submission to the last shard's results file, merges the shard files with `calibration-mc --merge`,
#    and compares the two JSON summaries byte for byte.
# 4. Stops the daemons it started.
#
# On a real cluster only step 3's sbatch line is needed (with your partition and account):
#   sbatch --array=0-9 --wrap 'calibration-mc -n 100 --first-seed 1 --json \
#          --shard $SLURM_ARRAY_TASK_ID/10 --shard-out shards --work work-$SLURM_ARRAY_TASK_ID'
#   calibration-mc --merge shards/results.shard-*-of-10.json --json > summary.json
#
# Exit status: 0 when the merged summary equals the unsharded one; 1 when it does not, or a
# task failed; 2 on a bad argument; 3 when Slurm could not be installed or started here (the
# machine, not the campaign: .ci/run reports it as a warning).
set -euo pipefail
N=${1:-4}
SHARDS=${2:-2}
WORK=$(realpath -m "${3:-/tmp/slurm-campaign}")  # absolute: it goes into slurm.conf
SCENARIO=${4:-gro-early-mission}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
case $N$SHARDS in *[!0-9]*) echo "N and SHARDS must be whole numbers" >&2; exit 2 ;; esac
[ "$SHARDS" -ge 1 ] && [ "$N" -ge "$SHARDS" ] || { echo "need N >= SHARDS >= 1" >&2; exit 2; }

if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
  echo "== installing slurm-wlm and munge (apt)"
  { DEBIAN_FRONTEND=noninteractive apt-get install -y -q slurm-wlm munge >/dev/null 2>&1 ||
    { apt-get update -q >/dev/null 2>&1 &&
      DEBIAN_FRONTEND=noninteractive apt-get install -y -q slurm-wlm munge >/dev/null; }; } ||
    { echo "could not install slurm-wlm and munge with apt" >&2; exit 3; }
fi
echo "== building calibration-mc"
(cd "$ROOT" && cargo build --release -q -p tests --bin calibration-mc)
MC="${CARGO_TARGET_DIR:-$ROOT/target}/release/calibration-mc"
[ "${MC:0:1}" = / ] || MC="$ROOT/$MC"

rm -rf "$WORK"
mkdir -p "$WORK"/{etc,state,spool,log,shards}
HOST=$(hostname -s)
CPUS=$(nproc)
MEM=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 512 ))
cat >"$WORK/etc/slurm.conf" <<EOF
ClusterName=gro
SlurmctldHost=$HOST
AuthType=auth/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$WORK/state
SlurmdSpoolDir=$WORK/spool
SlurmctldPidFile=$WORK/slurmctld.pid
SlurmdPidFile=$WORK/slurmd.pid
SlurmctldLogFile=$WORK/log/slurmctld.log
SlurmdLogFile=$WORK/log/slurmd.log
ReturnToService=2
NodeName=$HOST CPUs=$CPUS RealMemory=$MEM State=UNKNOWN
PartitionName=campaign Nodes=$HOST Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF="$WORK/etc/slurm.conf"

started=()
cleanup() {
  for p in "${started[@]}"; do kill "$p" 2>/dev/null || true; done
}
trap cleanup EXIT
echo "== starting munged, slurmctld, slurmd (logs in $WORK/log)"
start_munge() {
  mkdir -p /etc/munge /run/munge /var/lib/munge /var/log/munge &&
    { [ -s /etc/munge/munge.key ] || dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key 2>/dev/null; } &&
    chmod 400 /etc/munge/munge.key || return 1
  if ! pgrep -x munged >/dev/null; then
    munged --force || return 1
    started+=("$(pgrep -n -x munged)")
  fi
}
start_munge || { echo "munge could not be started here (root needed)" >&2; exit 3; }
command -v slurmctld >/dev/null || { echo "no slurmctld" >&2; exit 3; }
slurmctld -D -f "$SLURM_CONF" >"$WORK/log/slurmctld.out" 2>&1 &
started+=($!)
slurmd -D -f "$SLURM_CONF" >"$WORK/log/slurmd.out" 2>&1 &
started+=($!)
for _ in $(seq 60); do
  sinfo -h -o %t 2>/dev/null | grep -qE '^(idle|mix|alloc)' && break
  sleep 1
done
sinfo -h -o "%P %t %c CPUs" | grep -qE ' (idle|mix|alloc) ' ||
  { echo "Slurm did not come up: $WORK/log" >&2; exit 3; }
sinfo -h -o "%P %t %c CPUs"

echo "== unsharded: calibration-mc -n $N ($SCENARIO)"
t0=$(date +%s.%N)
"$MC" -n "$N" --first-seed 1 --scenario "$SCENARIO" --work "$WORK/work-unsharded" --json \
  >"$WORK/unsharded.json" 2>"$WORK/log/unsharded.err"
t1=$(date +%s.%N)

echo "== job array: $SHARDS shards"
sbatch --wait --array=0-$((SHARDS - 1)) --cpus-per-task=1 -o "$WORK/log/shard-%a.out" \
  --wrap "\"$MC\" -n $N --first-seed 1 --scenario \"$SCENARIO\" --json \
          --shard \$SLURM_ARRAY_TASK_ID/$SHARDS --shard-out \"$WORK/shards\" \
          --work \"$WORK/work-\$SLURM_ARRAY_TASK_ID\"" >"$WORK/log/sbatch.out" ||
  { echo "the job array failed: $WORK/log/shard-*.out" >&2; exit 1; }
echo "   $(cat "$WORK/log/sbatch.out")"
# The array's end is its last results file (sbatch --wait polls at growing intervals, up to
# tens of seconds, so its return time is not the campaign's).
t2=$(for f in "$WORK"/shards/results.shard-*-of-"$SHARDS".json; do date -r "$f" +%s.%N; done | sort -n | tail -n 1)
"$MC" --merge "$WORK"/shards/results.shard-*-of-"$SHARDS".json --json >"$WORK/merged.json"

awk -v a="$t0" -v b="$t1" -v c="$t2" -v m="$SHARDS" 'BEGIN {
  printf "wall time: unsharded %.1f s; %d-task job array (submission to last results file) %.1f s; ratio %.2f\n",
    b - a, m, c - b, (c - b) / (b - a) }'
if cmp -s "$WORK/unsharded.json" "$WORK/merged.json"; then
  echo "merged summary of $SHARDS shards == unsharded summary (byte for byte, $N seeds)"
else
  echo "DIFFERENT: diff $WORK/unsharded.json $WORK/merged.json" >&2
  exit 1
fi
