#!/usr/bin/env bash
# Renders a scene as a Slurm job array on a one-node cluster started here,
# merges it with the job that depends on the array, and checks the merged
# image is byte-identical to a single render. Needs root (the daemons run as
# root), munge and slurm-wlm (Debian's packages; .ci/run installs them).
# Everything lives in a fresh temporary folder: a private munge socket and
# key, slurm.conf on unused ports, the daemons in a network namespace whose
# only interface is the loopback (unshare --net; without it the test falls
# back to CommunicationParameters=NoInAddrAny and fails if a daemon still
# listens beyond 127.0.0.1), no systemd, no cgroups (proctrack/linuxproc, task/none). The daemons it starts
# are stopped on exit. If they cannot start, it says so and FAILS.
#     sh test/slurm_ci.sh [RRV]          (from the repository root)
set -u
cd "$(dirname "$0")/.."
# In a network namespace of its own the loopback is the only interface, so
# no daemon can listen beyond it whatever address it binds.
if [ -z "${RRV_SLURM_NETNS:-}" ]; then
    if RRV_SLURM_NETNS=1 unshare --net true 2>/dev/null; then
        exec env RRV_SLURM_NETNS=1 unshare --net bash "$0" "$@"
    fi
    echo "slurm: no network namespace (unshare --net failed): relying on NoInAddrAny and checking"
    RRV_SLURM_NETNS=0
fi
if [ "$RRV_SLURM_NETNS" = 1 ]; then
    # getaddrinfo's AI_ADDRCONFIG (slurm binds through it) finds nothing
    # where only 127.0.0.1 and ::1 exist: a second address on lo itself.
    { ip link set lo up && ip addr add 10.254.254.1/32 dev lo; } ||
        { echo "FAIL slurm: cannot set up the loopback in the network namespace"; exit 1; }
fi
rrv=$(realpath "${1:-./rrv}")
scene=$(realpath scenes/smoke.rrv)
tiles=${RRV_SLURM_TILES:-4}
render_args=${RRV_SLURM_RENDER_ARGS:---spp 4}
timeout=${RRV_SLURM_TIMEOUT:-150}
port=${RRV_SLURM_PORT:-26817}

fail() { echo "FAIL slurm: $*"; dump_logs; exit 1; }
pids=""
work=$(mktemp -d /tmp/rrv-slurm.XXXXXX)
chmod 755 "$work"
dump_logs() {
    for f in "$work"/munged.log "$work"/slurmctld.log "$work"/slurmd.log "$work"/farm/logs/*.log; do
        [ -s "$f" ] && { echo "--- $f (last lines)"; tail -n 15 "$f"; }
    done
}
stop() {
    for p in $pids; do kill "$p" 2>/dev/null; done
    for p in $pids; do
        for _ in 1 2 3 4 5 6 7 8 9 10; do kill -0 "$p" 2>/dev/null || break; sleep 0.5; done
        kill -9 "$p" 2>/dev/null
    done
    [ -n "${KEEP_SLURM_WORK:-}" ] || rm -rf "$work"
}
trap stop EXIT INT TERM

for tool in munged slurmctld slurmd sbatch squeue sinfo; do
    command -v $tool >/dev/null || fail "$tool is not installed (apt-get install munge slurm-wlm)"
done
[ "$(id -u)" = 0 ] || fail "the test starts slurmctld and slurmd as root; run it as root"
[ -x "$rrv" ] || fail "no rrv at $rrv (make rrv)"

# munge: a private key and socket, so a munged already running is not touched.
dd if=/dev/urandom of="$work/munge.key" bs=1024 count=1 2>/dev/null
chmod 400 "$work/munge.key"
mkdir -p "$work/munge" && chmod 700 "$work/munge"
munged --force --socket="$work/munge/munge.sock" --key-file="$work/munge.key" \
    --pid-file="$work/munged.pid" --log-file="$work/munged.log" --seed-file="$work/munge.seed" \
    || fail "munged did not start"
for _ in $(seq 50); do [ -s "$work/munged.pid" ] && break; sleep 0.1; done
[ -s "$work/munged.pid" ] || fail "munged wrote no pid file"
pids="$(cat "$work/munged.pid")"

mkdir -p "$work/state" "$work/spool"
: > "$work/plugstack.conf"
cat > "$work/slurm.conf" <<CONF
ClusterName=rrvci
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SrunPortRange=$((port + 2))-$((port + 40))
$([ "$RRV_SLURM_NETNS" = 1 ] || echo CommunicationParameters=NoInAddrAny)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$work/munge/munge.sock
CredType=cred/munge
PlugStackConfig=$work/plugstack.conf
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
MpiDefault=none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
SchedulerType=sched/backfill
SlurmdTimeout=30
NodeName=localhost NodeAddr=127.0.0.1 NodeHostname=localhost CPUs=$(nproc) State=UNKNOWN
PartitionName=ci Nodes=localhost Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF="$work/slurm.conf"

slurmctld -D -c -f "$SLURM_CONF" >>"$work/slurmctld.log" 2>&1 &
pids="$pids $!"
slurmd -D -N localhost -f "$SLURM_CONF" >>"$work/slurmd.log" 2>&1 &
pids="$pids $!"

state=""
for _ in $(seq 60); do
    state=$(sinfo -h -n localhost -o %T 2>/dev/null | head -1)
    [ "$state" = idle ] && break
    sleep 0.5
done
[ "$state" = idle ] || fail "the one-node cluster did not come up (node state \"$state\" after 30 s)"
for p in $pids; do kill -0 "$p" 2>/dev/null || fail "a daemon (pid $p) died"; done
if [ "$RRV_SLURM_NETNS" = 1 ]; then
    others=$(ip -o link show | awk -F': ' '$2 != "lo" { print $2 }')
    [ -z "$others" ] || fail "the namespace has interfaces beyond the loopback: $others"
else
    wide=$(ss -ltnH 2>/dev/null | awk -v a=":$port" -v b=":$((port + 1))" '($4 ~ a"$" || $4 ~ b"$") && $4 !~ /^127\./')
    [ -z "$wide" ] || fail "a daemon listens beyond the loopback: $wide"
fi
echo "slurm: one node up: slurmctld, slurmd on port $port, loopback only (own network namespace: $RRV_SLURM_NETNS), munged"

# The farm: tiles as an array, the merge after it.
"$rrv" farm slurm "$scene" -o "$work/merged.exr" --tiles "$tiles" --dir "$work/farm" --partition ci \
    ${RRV_SLURM_FARM_ARGS:-} -- $render_args >/dev/null || fail "rrv farm slurm failed"
wait_jobs() {
    local start=$SECONDS
    while [ -n "$(squeue -h -o %i 2>/dev/null)" ]; do
        [ $((SECONDS - start)) -lt "$timeout" ] || fail "jobs still queued after ${timeout} s: $(squeue -h -o '%i %T %R')"
        sleep 1
    done
}
t0=$(date +%s.%N)
sh "$work/farm/submit.sh" || fail "sbatch refused the jobs"
wait_jobs
t1=$(date +%s.%N)
[ -s "$work/merged.exr" ] || fail "the merge job wrote no image"
TIMEFORMAT="%U %S"
{ time "$rrv" render "$scene" -o "$work/single.exr" -q $render_args 2>"$work/single.err"; } 2>"$work/single.time" ||
    fail "the single render failed: $(cat "$work/single.err")"
t2=$(date +%s.%N)
cmp -s "$work/merged.exr" "$work/single.exr" || fail "the merged image differs from a single render"
echo "PASS slurm: $tiles tiles as a job array, merged after it, byte-identical to a single render"
tasks=$(cat "$work"/farm/logs/tile_*.log | sed -n 's/.* in \([0-9.]*\) s:.*/\1/p' | awk '{ t += $1 } END { printf "%.2f", t }')
awk -v a="$t0" -v b="$t1" -v c="$t2" -v t="$tasks" -v u="$(cat "$work/single.time")" 'BEGIN { split(u, us, " ");
    printf "slurm: submit to merged %.2f s wall (tasks rendered %s s in all); single render %.2f s wall, %.2f s user+sys\n",
        b - a, t, c - b, us[1] + us[2] }'

# Resume: one part lost, the same jobs submitted again render only it.
rm -f "$work/farm/parts/tile_1.exr" "$work/merged.exr"
sh "$work/farm/submit.sh" >/dev/null || fail "sbatch refused the jobs again"
wait_jobs
cmp -s "$work/merged.exr" "$work/single.exr" || fail "the resumed merge differs from a single render"
kept=$(grep -l "is complete" "$work"/farm/logs/tile_*.log | wc -l)
[ "$kept" -eq $((tiles - 1)) ] || fail "a resubmission kept $kept complete parts, not $((tiles - 1))"
echo "PASS slurm: a resubmitted array renders only the missing part ($kept kept)"
