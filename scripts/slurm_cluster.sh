#!/usr/bin/env bash
# A one-node Slurm cluster on localhost, without systemd, for tests and for
# users without a cluster. Everything (config, state, logs, munge key and
# socket) lives under one folder DIR; nothing under /etc is touched.
#
# Usage:
#   scripts/slurm_cluster.sh install            install the Debian packages (idempotent)
#   scripts/slurm_cluster.sh start DIR          start munged + slurmctld + slurmd, wait for idle;
#                                               last stdout line: SLURM_CONF=DIR/etc/slurm.conf
#   scripts/slurm_cluster.sh stop DIR           shut everything down (safe to repeat)
#   scripts/slurm_cluster.sh stop-node DIR [--kill-jobs]
#                                               stop slurmd only (a lost node); with --kill-jobs
#                                               also kill the running job steps (a crashed node)
#   scripts/slurm_cluster.sh start-node DIR     start slurmd again
#   scripts/slurm_cluster.sh status DIR         print daemon pids, sinfo and squeue
#
# Then: `source DIR/env.sh` (exports SLURM_CONF) and use sbatch/squeue/sinfo.
# Environment: SLURM_CTLD_PORT (default 16817), SLURM_D_PORT (default 16818),
#              SLURM_START_TIMEOUT (seconds to wait for idle, default 30),
#              SLURM_SLURMD_TIMEOUT (5), SLURM_MESSAGE_TIMEOUT (5), SLURM_CRED_EXPIRE (10,
#              also the delay before a requeued job may start again).
# Progress and errors go to stderr; stdout carries only the results.
set -euo pipefail

PROGS=(munged slurmctld slurmd sbatch squeue sinfo scontrol)
CTLD_PORT=${SLURM_CTLD_PORT:-16817}
D_PORT=${SLURM_D_PORT:-16818}
START_TIMEOUT=${SLURM_START_TIMEOUT:-30}
STOP_TIMEOUT=${SLURM_STOP_TIMEOUT:-15}
SLURMD_TIMEOUT=${SLURM_SLURMD_TIMEOUT:-5}
CRED_EXPIRE=${SLURM_CRED_EXPIRE:-10}
MESSAGE_TIMEOUT=${SLURM_MESSAGE_TIMEOUT:-5}

log() { echo "slurm_cluster: $*" >&2; }
die() { echo "slurm_cluster: error: $*" >&2; exit 1; }

usage() {
    sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0" >&2
    exit 2
}

# Path of a program, also looking in the sbin folders a non-root PATH lacks.
find_prog() {
    local p=$1 d
    if command -v "$p" >/dev/null 2>&1; then command -v "$p"; return 0; fi
    for d in /usr/sbin /sbin /usr/local/sbin; do
        if [[ -x $d/$p ]]; then echo "$d/$p"; return 0; fi
    done
    return 1
}

missing_progs() {
    local p out=()
    for p in "$@"; do find_prog "$p" >/dev/null || out+=("$p"); done
    echo "${out[*]-}"
}

cmd_install() {
    local missing
    missing=$(missing_progs slurmctld slurmd sbatch munged)
    if [[ -z $missing ]]; then
        log "already installed (slurmctld slurmd sbatch munged found)"
        return 0
    fi
    log "installing Slurm and munge (missing: $missing)"
    local sudo=()
    if [[ $(id -u) -ne 0 ]]; then
        command -v sudo >/dev/null 2>&1 || die "not root and no sudo: cannot install packages"
        sudo=(sudo)
    fi
    "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update
    "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends \
        slurmctld slurmd slurm-client munge
    missing=$(missing_progs "${PROGS[@]}")
    [[ -z $missing ]] || die "installed, but still missing: $missing"
    log "installed"
}

# Absolute path of DIR (created when $2 is "create").
resolve_dir() {
    local dir=${1:-}
    [[ -n $dir ]] || die "missing DIR argument (see: $0 help)"
    if [[ ${2:-} == create ]]; then
        mkdir -p "$dir" || die "cannot create $dir"
    fi
    [[ -d $dir ]] || die "$dir is not a folder"
    (cd "$dir" && pwd -P)
}

set_paths() {
    D=$1
    CONF=$D/etc/slurm.conf
    SOCK=$D/munge/munge.socket
    export SLURM_CONF=$CONF
    NODE=$(hostname -s)
}

# Whether a process is alive; a zombie (exited, not yet reaped by its parent,
# which for a daemon may be a slow init) counts as dead.
alive() {
    local st
    kill -0 "$1" 2>/dev/null || return 1
    st=$(cat "/proc/$1/stat" 2>/dev/null) || return 1
    st=${st##*) }; st=${st%% *}
    [[ -n $st && $st != Z && $st != X ]]
}

pid_of() { # pid from a pid file, if that process is alive
    local f=$1 pid
    [[ -s $f ]] || return 1
    pid=$(tr -dc '0-9' <"$f")
    [[ -n $pid ]] && alive "$pid" || return 1
    echo "$pid"
}

# Pids of Slurm processes (slurmstepd, leftover daemons) of this cluster: they
# all inherit its SLURM_CONF. Only these names, never the caller's shell.
pids_with_conf() {
    local pid
    for pid in $(pgrep -x slurmstepd; pgrep -x slurmd; pgrep -x slurmctld); do
        alive "$pid" || continue
        if tr '\0' '\n' 2>/dev/null <"/proc/$pid/environ" | grep -qxF "SLURM_CONF=$CONF"; then
            echo "$pid"
        fi
    done
}

# All descendants of the given pids (children first listed after parents).
descendants() {
    local -a queue=("$@") out=()
    local p c
    while ((${#queue[@]})); do
        p=${queue[0]}; queue=("${queue[@]:1}")
        for c in $(pgrep -P "$p" 2>/dev/null || true); do
            out+=("$c"); queue+=("$c")
        done
    done
    echo "${out[*]-}"
}

# Wait up to $1 seconds for all the given pids to exit; returns 1 on timeout.
wait_pids() {
    local timeout=$1; shift
    local end=$((SECONDS + timeout)) p alive
    while :; do
        alive=0
        for p in "$@"; do alive "$p" && alive=1; done
        ((alive)) || return 0
        ((SECONDS < end)) || return 1
        sleep 0.1
    done
}

kill_and_wait() { # kill_and_wait TIMEOUT PID... : SIGTERM, wait, SIGKILL
    local timeout=$1; shift
    (($#)) || return 0
    kill -TERM "$@" 2>/dev/null || true
    if ! wait_pids "$timeout" "$@"; then
        log "still alive after ${timeout}s, sending SIGKILL: $*"
        kill -KILL "$@" 2>/dev/null || true
        wait_pids 5 "$@" || true
    fi
}

show_logs() {
    local f
    for f in "$D"/log/munged.log "$D"/log/slurmctld.log "$D"/log/slurmd.log; do
        [[ -s $f ]] || continue
        echo "----- tail of $f -----" >&2
        tail -n 25 "$f" >&2
    done
}

fail_start() {
    echo "slurm_cluster: error: $*" >&2
    show_logs
    log "stopping what was started"
    cmd_stop_dir || true
    exit 1
}

port_busy() {
    command -v ss >/dev/null 2>&1 || return 1
    ss -Hltn "sport = :$1" 2>/dev/null | grep -q .
}

write_conf() {
    local cpus mem_mb
    cpus=$(nproc)
    # The node's memory, so that jobs asking for some (sbatch --mem) fit; Slurm's
    # default of 1 MB rejects them.
    mem_mb=$(awk '/^MemTotal:/ {print int($2 / 1024)}' /proc/meminfo)
    cat >"$CONF" <<EOF
# Written by scripts/slurm_cluster.sh: a one-node cluster on localhost.
ClusterName=ci
SlurmctldHost=$NODE(127.0.0.1)
SlurmUser=root
SlurmdUser=root
SlurmctldPort=$CTLD_PORT
SlurmdPort=$D_PORT
AuthType=auth/munge
# cred_expire also delays the restart of a requeued job (default 120 s).
AuthInfo=socket=$SOCK,cred_expire=$CRED_EXPIRE
CredType=cred/munge
StateSaveLocation=$D/state
SlurmdSpoolDir=$D/spool
SlurmctldPidFile=$D/run/slurmctld.pid
SlurmdPidFile=$D/run/slurmd.pid
SlurmctldLogFile=$D/log/slurmctld.log
SlurmdLogFile=$D/log/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc=$D/log/jobcomp.txt
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
# Small timeouts so that a lost node is noticed quickly and jobs stop fast:
# measured, a stopped slurmd is DOWN after ~15 s with 5/5 (~26 s with the
# defaults 300/10; MessageTimeout, not only SlurmdTimeout, sets the pace).
# Schedule on every job's end, at once: measured, 8 one-second tasks on 2 CPUs ran
# in 12.6 s with the defaults and 7.8 s with these (a 2 s cycle per wave, not 3).
SchedulerParameters=sched_min_interval=0,batch_sched_delay=0,sched_interval=1
SlurmdTimeout=$SLURMD_TIMEOUT
MessageTimeout=$MESSAGE_TIMEOUT
SlurmctldTimeout=10
KillWait=5
MinJobAge=300
NodeName=$NODE NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=ci Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
    cat >"$D/env.sh" <<EOF
# Source this to use the one-node Slurm cluster in $D.
export SLURM_CONF=$CONF
EOF
}

start_munged() {
    if pid_of "$D/run/munged.pid" >/dev/null; then
        log "munged already running"
        return 0
    fi
    if [[ ! -s $D/munge/munge.key ]]; then
        (umask 077 && head -c 1024 /dev/urandom >"$D/munge/munge.key")
    fi
    chmod 400 "$D/munge/munge.key"
    rm -f "$SOCK" "$SOCK.lock"
    "$(find_prog munged)" --key-file="$D/munge/munge.key" --socket="$SOCK" \
        --pid-file="$D/run/munged.pid" --log-file="$D/log/munged.log" \
        --seed-file="$D/munge/seed" ||
        fail_start "munged failed to start"
    local end=$((SECONDS + 10))
    until [[ -S $SOCK ]]; do
        ((SECONDS < end)) || fail_start "munged socket $SOCK did not appear"
        sleep 0.1
    done
}

start_slurmd() {
    if pid_of "$D/run/slurmd.pid" >/dev/null; then
        log "slurmd already running"
        return 0
    fi
    port_busy "$D_PORT" && fail_start "port $D_PORT (slurmd) is in use; set SLURM_D_PORT"
    "$(find_prog slurmd)" -f "$CONF" || fail_start "slurmd failed to start"
}

node_state() { "$(find_prog sinfo)" -h -o %t 2>/dev/null | head -n 1 || true; }

cmd_start() {
    local missing
    missing=$(missing_progs "${PROGS[@]}")
    [[ -z $missing ]] || die "missing programs: $missing (run: $0 install)"
    set_paths "$(resolve_dir "${1:-}" create)"
    local ctld_pid
    if ctld_pid=$(pid_of "$D/run/slurmctld.pid"); then
        die "a cluster is already running in $D (slurmctld pid $ctld_pid); run: $0 stop $D"
    fi
    mkdir -p "$D"/{etc,state,spool,log,run,munge}
    # A fresh cluster each time: no jobs or node states from an earlier run.
    find "$D/state" "$D/spool" -mindepth 1 -delete
    # munged demands that the socket folder and every folder above it be
    # searchable by all ("execute permissions for all required"): mktemp -d
    # gives 700, so open DIR up too.
    chmod 755 "$D" "$D/munge"
    write_conf

    local t0=$SECONDS
    start_munged
    port_busy "$CTLD_PORT" && fail_start "port $CTLD_PORT (slurmctld) is in use; set SLURM_CTLD_PORT"
    # -c: clear saved state; -i: ignore unreadable state files.
    "$(find_prog slurmctld)" -c -i -f "$CONF" || fail_start "slurmctld failed to start"
    start_slurmd

    local end=$((SECONDS + START_TIMEOUT)) st=""
    while :; do
        st=$(node_state)
        [[ $st == idle ]] && break
        pid_of "$D/run/slurmctld.pid" >/dev/null || [[ $((SECONDS - t0)) -lt 3 ]] ||
            fail_start "slurmctld is not running"
        ((SECONDS < end)) || fail_start "node not idle after ${START_TIMEOUT}s (sinfo state: '${st:-none}')"
        sleep 0.2
    done
    log "cluster up in $D ($((SECONDS - t0))s; node $NODE, ports $CTLD_PORT/$D_PORT)"
    echo "SLURM_CONF=$CONF"
}

# Stop everything of the cluster in $D (set_paths done).
cmd_stop_dir() {
    local pids=() p f
    for f in slurmctld slurmd; do
        p=$(pid_of "$D/run/$f.pid") && pids+=("$p")
    done
    if ((${#pids[@]})); then
        # scontrol shutdown stops slurmctld and slurmd; SIGTERM does the same
        # when slurmctld is gone already or does not pass the word on.
        if [[ -f $CONF ]] && pid_of "$D/run/slurmctld.pid" >/dev/null &&
            timeout 10 "$(find_prog scontrol)" shutdown >/dev/null 2>&1; then
            wait_pids 5 "${pids[@]}" || kill -TERM "${pids[@]}" 2>/dev/null || true
        else
            kill -TERM "${pids[@]}" 2>/dev/null || true
        fi
    fi
    if ((${#pids[@]})) && ! wait_pids "$STOP_TIMEOUT" "${pids[@]}"; then
        log "daemons still alive after ${STOP_TIMEOUT}s, killing: ${pids[*]}"
        kill -KILL "${pids[@]}" 2>/dev/null || true
        wait_pids 5 "${pids[@]}" || true
    fi
    # Leftover job steps (slurmstepd and their jobs) of this cluster.
    local left=()
    mapfile -t left < <(pids_with_conf)
    if ((${#left[@]})); then
        local kids
        kids=$(descendants "${left[@]}")
        log "killing leftover processes: ${left[*]} $kids"
        # shellcheck disable=SC2086
        kill -KILL "${left[@]}" $kids 2>/dev/null || true
    fi
    # SIGTERM is faster than `munged -s` (which polls for about 2 s).
    if p=$(pid_of "$D/run/munged.pid"); then
        kill_and_wait 5 "$p"
    elif [[ -S $SOCK ]] && find_prog munged >/dev/null; then
        timeout 10 "$(find_prog munged)" -s --socket="$SOCK" >/dev/null 2>&1 || true
    fi
    rm -f "$D"/run/*.pid
}

cmd_stop() {
    local dir=${1:-}
    [[ -n $dir ]] || die "missing DIR argument"
    if [[ ! -d $dir ]]; then
        log "nothing to stop: $dir does not exist"
        return 0
    fi
    set_paths "$(resolve_dir "$dir")"
    cmd_stop_dir
    log "stopped cluster in $D"
}

cmd_stop_node() {
    set_paths "$(resolve_dir "${1:-}")"
    local kill_jobs=0
    [[ ${2:-} == --kill-jobs ]] && kill_jobs=1
    [[ -z ${2:-} || $kill_jobs == 1 ]] || die "unknown option ${2}"
    local p
    if p=$(pid_of "$D/run/slurmd.pid"); then
        kill_and_wait 10 "$p"
        log "slurmd stopped (pid $p)"
    else
        log "slurmd was not running"
    fi
    if ((kill_jobs)); then
        local steps=() q
        for q in $(pids_with_conf); do
            [[ $(cat "/proc/$q/comm" 2>/dev/null) == slurmstepd ]] && steps+=("$q")
        done
        if ((${#steps[@]})); then
            local kids
            kids=$(descendants "${steps[@]}")
            # shellcheck disable=SC2086
            kill -KILL "${steps[@]}" $kids 2>/dev/null || true
            log "killed job steps: ${steps[*]} $kids"
        fi
    fi
}

cmd_start_node() {
    set_paths "$(resolve_dir "${1:-}")"
    [[ -f $CONF ]] || die "no cluster in $D (run: $0 start $D)"
    pid_of "$D/run/slurmctld.pid" >/dev/null || die "slurmctld is not running in $D"
    # fail_start would tear down the cluster: report only.
    if pid_of "$D/run/slurmd.pid" >/dev/null; then
        log "slurmd already running"
        return 0
    fi
    port_busy "$D_PORT" && die "port $D_PORT (slurmd) is in use"
    if ! "$(find_prog slurmd)" -f "$CONF"; then
        show_logs
        die "slurmd failed to start"
    fi
    # ReturnToService=2: the node leaves DOWN as soon as slurmd registers.
    local end=$((SECONDS + START_TIMEOUT)) st=""
    while :; do
        st=$(node_state)
        [[ $st =~ ^(idle|alloc|mix|comp)$ ]] && break
        if ((SECONDS >= end)); then
            show_logs
            die "node not back after ${START_TIMEOUT}s (sinfo state: '${st:-none}')"
        fi
        sleep 0.2
    done
    log "slurmd started, node $st"
}

cmd_status() {
    set_paths "$(resolve_dir "${1:-}")"
    local f p rc=0
    for f in munged slurmctld slurmd; do
        if p=$(pid_of "$D/run/$f.pid"); then
            echo "$f: running (pid $p)"
        else
            echo "$f: stopped"; rc=1
        fi
    done
    if pid_of "$D/run/slurmctld.pid" >/dev/null; then
        "$(find_prog sinfo)" -N -o '%N %t %E' 2>&1 || true
        "$(find_prog squeue)" -o '%i %T %r' 2>&1 || true
    fi
    return $rc
}

case ${1:-} in
install) cmd_install ;;
start) cmd_start "${2:-}" ;;
stop) cmd_stop "${2:-}" ;;
stop-node) cmd_stop_node "${2:-}" "${3:-}" ;;
start-node) cmd_start_node "${2:-}" ;;
status) cmd_status "${2:-}" ;;
help | -h | --help) usage ;;
*) usage ;;
esac
