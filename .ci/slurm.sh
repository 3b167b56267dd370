#!/usr/bin/env bash
# A real single-node Slurm cluster on this machine (Debian's slurm-wlm and munge), for tests/test_sweep_slurm.py:
# munged, slurmctld and slurmd as plain daemons (no systemd), one partition, jobs run as the submitting user.
# Idempotent: a cluster this script started and that still answers is left running; run it again after a reboot
# or a config change. Exits non-zero with the failing daemon's own error when the cluster does not come up.
#
# Settings that make a short test possible, all documented in slurm.conf(5):
#   OverTimeLimit=1                the hard kill (SIGTERM) a minute after the time limit: a run stops and requeues at
#                                  the --signal warning before the limit, and on a loaded machine finishing the chunk
#                                  it is in (compiling kernels, on a cold cache) can take longer than the 30 s that
#                                  would otherwise separate the warning from the kill
#   AuthInfo=cred_expire=10        a requeued job may start again after 11 s (default 121 s)
#   SchedulerParameters=sched_interval=2,bf_interval=2
#                                  pending jobs (a requeued one) are tried every 2 s (default 60 s / 30 s)
#   KillWait=10                    SIGKILL 10 s after the SIGTERM at the time limit (default 30 s)
# slurmctld checks time limits (and sends --signal warnings) every 30 s, a compile-time constant (PERIODIC_TIMEOUT).
#
# Environment: SLURM_CI_DIR (state, spool and logs; default /var/tmp/taichimyxo-slurm), SLURM_CI_TIMEOUT_S (how
# long to wait for the node to be idle; default 120).
set -euo pipefail

dir="${SLURM_CI_DIR:-/var/tmp/taichimyxo-slurm}"
wait_s="${SLURM_CI_TIMEOUT_S:-120}"
conf_dir=/etc/slurm
sudo=""
if [ "$(id -u)" != 0 ]; then sudo="sudo"; fi

fail() {
    echo "slurm.sh: $*" >&2
    for log in "$dir/log/slurmctld.log" "$dir/log/slurmd.log" /var/log/munge/munged.log; do
        if [ -s "$log" ]; then echo "--- last lines of $log:" >&2; tail -n 15 "$log" >&2; fi
    done
    exit 1
}

# 1. packages
if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null || ! command -v sbatch >/dev/null \
        || ! command -v munged >/dev/null; then
    $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends slurm-wlm munge \
        >/tmp/taichimyxo-slurm-apt.log 2>&1 || {
        $sudo apt-get update >/dev/null 2>&1 || true
        $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends slurm-wlm munge \
            >/tmp/taichimyxo-slurm-apt.log 2>&1 || { tail -n 20 /tmp/taichimyxo-slurm-apt.log >&2;
                                                      fail "apt-get install slurm-wlm munge failed"; }
    }
fi

# 2. the configuration, from what slurmd sees of this machine
host="$(hostname -s)"
hw="$(slurmd -C | head -n 1)"              # NodeName=... CPUs=2 Boards=1 SocketsPerBoard=1 ... RealMemory=24105
cpus="$(sed -n 's/.* CPUs=\([0-9]*\).*/\1/p' <<<"$hw")"
mem="$(sed -n 's/.* RealMemory=\([0-9]*\).*/\1/p' <<<"$hw")"
[ -n "$cpus" ] && [ -n "$mem" ] || fail "cannot read CPUs and RealMemory from 'slurmd -C': $hw"
mem=$((mem * 9 / 10))                      # leave the OS some room
$sudo mkdir -p "$dir/state" "$dir/spool" "$dir/log" "$dir/run" "$conf_dir"
new_conf="$(mktemp)"
cat >"$new_conf" <<EOF
# written by taichimyxo .ci/slurm.sh: a single-node test cluster
ClusterName=taichimyxo
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=cred_expire=10
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/run/slurmctld.pid
SlurmdPidFile=$dir/run/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
SlurmctldPort=6817
SlurmdPort=6818
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SwitchType=switch/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
DefMemPerCPU=1024
SchedulerType=sched/backfill
SchedulerParameters=sched_interval=2,bf_interval=2
ReturnToService=2
OverTimeLimit=1
KillWait=10
MinJobAge=600
SlurmctldTimeout=30
SlurmdTimeout=60
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
changed=1
if [ -f "$conf_dir/slurm.conf" ] && cmp -s "$new_conf" "$conf_dir/slurm.conf"; then changed=0; fi
$sudo cp "$new_conf" "$conf_dir/slurm.conf"
rm -f "$new_conf"

alive() { [ -s "$1" ] && $sudo kill -0 "$(cat "$1")" 2>/dev/null; }
stop() {
    if alive "$1"; then
        $sudo kill "$(cat "$1")"
        for _ in $(seq 50); do alive "$1" || break; sleep 0.2; done
    fi
}
if [ "$changed" = 1 ]; then
    stop "$dir/run/slurmd.pid"
    stop "$dir/run/slurmctld.pid"
fi

# 3. munge: a key (the package makes one; make it if missing) and the daemon, as the munge user
if [ ! -s /etc/munge/munge.key ]; then
    $sudo mungekey --create --force || fail "mungekey --create failed"
    $sudo chown munge:munge /etc/munge/munge.key
    $sudo chmod 400 /etc/munge/munge.key
fi
$sudo mkdir -p /run/munge /var/log/munge /var/lib/munge
$sudo chown munge:munge /run/munge /var/log/munge /var/lib/munge
if ! munge -n </dev/null 2>/dev/null | unmunge >/dev/null 2>&1; then
    $sudo runuser -u munge -- /usr/sbin/munged 2>"$dir/log/munged.err" \
        || fail "munged did not start: $(cat "$dir/log/munged.err")"
    for _ in $(seq 50); do munge -n </dev/null 2>/dev/null | unmunge >/dev/null 2>&1 && break; sleep 0.2; done
    munge -n </dev/null | unmunge >/dev/null || fail "munge does not work: $(munge -n </dev/null 2>&1 | unmunge 2>&1)"
fi

# 4. slurmctld and slurmd (daemonise themselves; -N: this node's name even when the hostname does not resolve)
if ! alive "$dir/run/slurmctld.pid"; then
    $sudo slurmctld 2>"$dir/log/slurmctld.err" || fail "slurmctld did not start: $(cat "$dir/log/slurmctld.err")"
fi
for _ in $(seq 100); do scontrol ping 2>/dev/null | grep -q UP && break; sleep 0.2; done
scontrol ping | grep -q UP || fail "slurmctld does not answer: $(scontrol ping 2>&1)"
if ! alive "$dir/run/slurmd.pid"; then
    $sudo slurmd -N "$host" 2>"$dir/log/slurmd.err" || fail "slurmd did not start: $(cat "$dir/log/slurmd.err")"
fi

# 5. wait until the node takes jobs
state=""
for _ in $(seq $((wait_s * 2))); do
    state="$(sinfo -h -n "$host" -o %t 2>/dev/null || true)"
    case "$state" in
        idle|mix|alloc) break ;;
        down*|drain*|fail*)
            # a node that was down (e.g. the daemons were restarted) is put back into service
            $sudo scontrol update NodeName="$host" State=RESUME 2>/dev/null || true ;;
    esac
    sleep 0.5
done
case "$state" in
    idle|mix|alloc) ;;
    *) fail "node $host is '$state', not idle, after ${wait_s} s: $(sinfo -N -l 2>&1; scontrol show node "$host" 2>&1 | grep -i reason)" ;;
esac
sinfo
