#!/usr/bin/env bash
# A single-node SLURM cluster on this machine, for testing the cluster route (profiles/slurm):
#
#   scripts/slurm_cluster.sh install   # Debian slurm-wlm, munge, libpmix-dev (idempotent, as root)
#   scripts/slurm_cluster.sh start     # install, then start munged, slurmctld, slurmd; wait for idle
#   scripts/slurm_cluster.sh status    # sinfo and the daemons' PIDs
#   scripts/slurm_cluster.sh stop      # stop every daemon by its PID; remove /etc/slurm/slurm.conf
#
# State (keys, spool, logs, PID files) lives in $PBMDEM_SLURM_STATE (default /tmp/pbmdem-slurm).
# No systemd and no cgroups: ProctrackType=proctrack/linuxproc, TaskPlugin=task/none. linuxproc
# finds a job's processes through their parents, so its SIGKILL after KillWait can miss a process
# re-parented to init (once, under load, a job step's `snakemake --target-jobs` outlived a cancel).
# proctrack/pgid was tried instead: a cancelled job step then ended within 2.5 s, before the DEM
# job's Python could record the interruption (no crash.json), which breaks the cancel contract
# the SLURM test checks. No
# accounting database: job status comes from squeue (the profile sets slurm-status-command), so
# MinJobAge keeps finished jobs visible for 10 minutes. The configuration has to be
# /etc/slurm/slurm.conf (the executor's job steps drop SLURM_CONF); an existing file that this
# script did not write is moved aside and put back by `stop`. Needs root.
set -euo pipefail

STATE=${PBMDEM_SLURM_STATE:-/tmp/pbmdem-slurm}
CONF=/etc/slurm/slurm.conf
MARK="# written by pbmdem scripts/slurm_cluster.sh"
PARTITION=${PBMDEM_SLURM_PARTITION:-debug}
START_TIMEOUT=${PBMDEM_SLURM_START_TIMEOUT:-60}

die() { echo "slurm_cluster: $*" >&2; exit 1; }
log() { echo "slurm_cluster: $*"; }

install_packages() {
    [ "$(id -u)" = 0 ] || die "must run as root (installs packages, writes $CONF, runs the daemons)"
    local need=()
    command -v slurmctld >/dev/null 2>&1 || need+=(slurm-wlm)
    command -v munged >/dev/null 2>&1 || need+=(munge)
    # srun --mpi=pmix needs the PMIx development files (the plugin dlopens libpmix.so)
    dpkg-query -W -f='${Status}' libpmix-dev 2>/dev/null | grep -q "ok installed" || need+=(libpmix-dev)
    if [ ${#need[@]} -gt 0 ]; then
        log "installing Debian packages: ${need[*]}"
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq
        apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
    fi
}

pid_alive() { [ -f "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null; }

show_logs() {
    for f in "$STATE"/log/*.log; do
        [ -f "$f" ] || continue
        echo "----- $f (last 40 lines)" >&2
        tail -n 40 "$f" >&2
    done
}

write_conf() {
    local host cpus mem
    host=$(hostname -s)
    cpus=$(nproc)
    mem=$(awk '/MemTotal/ {printf "%d", $2 / 1024 * 0.9}' /proc/meminfo)
    mkdir -p /etc/slurm
    if [ -f "$CONF" ] && ! grep -qF "$MARK" "$CONF"; then
        log "moving the existing $CONF to $STATE/slurm.conf.orig"
        mv "$CONF" "$STATE/slurm.conf.orig"
    fi
    cat > "$CONF" <<EOF
$MARK (state in $STATE)
ClusterName=pbmdem
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$STATE/munge/munge.socket.2
StateSaveLocation=$STATE/ctld
SlurmdSpoolDir=$STATE/d
SlurmctldPidFile=$STATE/run/slurmctld.pid
SlurmdPidFile=$STATE/run/slurmd.pid
SlurmctldLogFile=$STATE/log/slurmctld.log
SlurmdLogFile=$STATE/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
ReturnToService=2
KillWait=10
MinJobAge=600
SlurmdTimeout=60
InactiveLimit=0
SchedulerType=sched/backfill
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=$PARTITION Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
}

start() {
    install_packages
    if pid_alive "$STATE/run/slurmctld.pid" || pid_alive "$STATE/run/slurmd.pid"; then
        die "a cluster from $STATE is already running (scripts/slurm_cluster.sh stop first)"
    fi
    rm -rf "$STATE"
    mkdir -p "$STATE"/{munge,ctld,d,run,log}
    chmod 700 "$STATE" && chmod 755 "$STATE/munge"
    write_conf
    # munge: a fresh key for this cluster only
    dd if=/dev/urandom of="$STATE/munge.key" bs=1024 count=1 status=none
    chmod 400 "$STATE/munge.key"
    munged -F --force --key-file="$STATE/munge.key" --socket="$STATE/munge/munge.socket.2" \
        --pid-file="$STATE/run/munged.pid" --log-file="$STATE/log/munged.log" \
        --seed-file="$STATE/munge.seed" >"$STATE/log/munged.out" 2>&1 &
    echo $! > "$STATE/run/munged.pid.bg"
    for _ in $(seq 50); do [ -S "$STATE/munge/munge.socket.2" ] && break; sleep 0.1; done
    [ -S "$STATE/munge/munge.socket.2" ] || { show_logs; cat "$STATE/log/munged.out" >&2; stop; die "munged did not start"; }
    slurmctld -D -i >"$STATE/log/slurmctld.out" 2>&1 &
    echo $! > "$STATE/run/slurmctld.pid.bg"
    slurmd -D >"$STATE/log/slurmd.out" 2>&1 &
    echo $! > "$STATE/run/slurmd.pid.bg"
    local t0=$SECONDS state=""
    while [ $((SECONDS - t0)) -lt "$START_TIMEOUT" ]; do
        state=$(sinfo -h -o %T 2>/dev/null | head -n1 || true)
        [ "$state" = idle ] && break
        sleep 0.5
    done
    if [ "$state" != idle ]; then
        echo "slurm_cluster: the node is '${state:-unreachable}' after ${START_TIMEOUT} s; daemon logs:" >&2
        show_logs
        for f in "$STATE"/log/*.out; do echo "----- $f" >&2; tail -n 20 "$f" >&2; done
        stop
        exit 1
    fi
    log "cluster up in $((SECONDS - t0)) s: partition $PARTITION, node $(hostname -s), $(nproc) CPUs; state in $STATE"
}

stop() {
    local f pid
    # cancel this cluster's jobs first, so that no job step outlives its daemons
    if pid_alive "$STATE/run/slurmctld.pid.bg" && [ -n "$(squeue -h -o %i 2>/dev/null || true)" ]; then
        scancel --full $(squeue -h -o %i) 2>/dev/null || true
        for _ in $(seq 30); do [ -z "$(squeue -h -t R,CG,PD -o %i 2>/dev/null || true)" ] && break; sleep 0.5; done
    fi
    for name in slurmd slurmctld munged; do
        for f in "$STATE/run/$name.pid.bg" "$STATE/run/$name.pid"; do
            [ -f "$f" ] || continue
            pid=$(cat "$f")
            if kill -0 "$pid" 2>/dev/null; then
                kill -TERM "$pid" 2>/dev/null || true
                for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
                kill -0 "$pid" 2>/dev/null && kill -KILL "$pid" 2>/dev/null || true
            fi
            rm -f "$f"
        done
    done
    if [ -f "$CONF" ] && grep -qF "$MARK" "$CONF"; then
        rm -f "$CONF"
        [ -f "$STATE/slurm.conf.orig" ] && mv "$STATE/slurm.conf.orig" "$CONF"
    fi
    log "stopped"
}

status() {
    for name in munged slurmctld slurmd; do
        if pid_alive "$STATE/run/$name.pid.bg"; then echo "$name: running (PID $(cat "$STATE/run/$name.pid.bg"))"
        else echo "$name: not running"; fi
    done
    sinfo 2>&1 || true
}

case "${1:-}" in
    install) install_packages ;;
    start) start ;;
    stop) stop ;;
    status) status ;;
    logs) show_logs ;;
    *) die "usage: $0 install|start|stop|status|logs" ;;
esac
