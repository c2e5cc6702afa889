#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, for `crease experiment run --executor
# slurm` and its test (issue 20). Facts it relies on: ../shared/SLURM.md (Debian 12's
# slurmctld, slurmd, slurm-client 22.05 and munge 0.5.15, as root, without systemd).
#
#   scripts/slurm_local.sh up     [STATE_DIR]   start munged, slurmctld, slurmd; wait for `idle`
#   scripts/slurm_local.sh down   [STATE_DIR]   cancel its jobs, stop the daemons by PID
#   scripts/slurm_local.sh status [STATE_DIR]   daemons, node state and queue
#   scripts/slurm_local.sh env    [STATE_DIR]   the line to eval: export SLURM_CONF=…
#
# Everything lives in STATE_DIR (default ${CREASE_SLURM_DIR:-/tmp/crease-slurm}):
# slurm.conf, the munge key and socket, the daemons' state, logs and PID files.
# Nothing is written to /etc. Clients find the cluster through SLURM_CONF
# (STATE_DIR/slurm.conf); `up` prints the export line. Ports: CREASE_SLURM_PORT
# (slurmctld, default 6917) and the next one (slurmd), so that services the packages
# may have started on 6817/6818 do not interfere.
set -euo pipefail

cmd="${1:-}"
state="$(realpath -m "${2:-${CREASE_SLURM_DIR:-/tmp/crease-slurm}}")"
port="${CREASE_SLURM_PORT:-6917}"
conf="$state/slurm.conf"
say() { printf '[slurm_local] %s\n' "$*" >&2; }
die() { say "error: $*"; exit 1; }

alive() {  # alive PIDFILE: the process of the PID file runs
  [ -s "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null
}

require_tools() {
  [ "$(id -u)" -eq 0 ] || die "must run as root (slurmd starts jobs as their user; SlurmUser=root)"
  local t missing=()
  for t in munged slurmctld slurmd sbatch squeue sinfo scancel; do
    command -v "$t" >/dev/null 2>&1 || missing+=("$t")
  done
  [ ${#missing[@]} -eq 0 ] ||
    die "missing ${missing[*]}: install the Debian packages slurmctld slurmd slurm-client munge (scripts/setup.sh does)"
}

node_name() {  # node_name "NodeName=vm CPUs=2 …" → vm
  local first="${1%% *}"
  echo "${first#NodeName=}"
}

write_config() {
  local host node
  host="$(hostname -s)"
  # The first line of `slurmd -C` (the full Sockets/Cores/Threads), else slurmd
  # complains that the node's socket/core boundaries were reconfigured.
  node="$(slurmd -C | head -n 1)"
  [[ "$node" == NodeName=* ]] || die "slurmd -C printed no node line: $node"
  mkdir -p "$state"/{munge,ctld,spool,log}
  # munged's socket must be reachable by all: its folder and every folder above it o+x.
  chmod 711 "$state" "$state/munge"
  local d="$state"
  while [ "$d" != "/" ]; do
    [ "$(( 0$(stat -c %a "$d") & 1 ))" -eq 1 ] ||
      die "$d is not searchable by others (o+x), which munged requires of its socket's folders: chmod o+x it or pick another STATE_DIR"
    d="$(dirname "$d")"
  done
  if [ ! -s "$state/munge/munge.key" ]; then
    dd if=/dev/urandom of="$state/munge/munge.key" bs=1024 count=1 status=none
  fi
  chmod 0400 "$state/munge/munge.key"
  cat > "$conf.tmp" <<EOF
# Written by crease scripts/slurm_local.sh: a single-node cluster on $host.
ClusterName=crease
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$state/munge/munge.socket
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$state/ctld
SlurmdSpoolDir=$state/spool
SlurmctldPidFile=$state/slurmctld.pid
SlurmdPidFile=$state/slurmd.pid
SlurmctldLogFile=$state/log/slurmctld.log
SlurmdLogFile=$state/log/slurmd.log
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
ReturnToService=2
SchedulerParameters=batch_sched_delay=0,sched_min_interval=0
DependencyParameters=kill_invalid_depend
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc=$state/log/jobcomp.log
$node NodeAddr=127.0.0.1 State=UNKNOWN
PartitionName=local Nodes=$(node_name "$node") Default=YES MaxTime=INFINITE State=UP
EOF
  mv "$conf.tmp" "$conf"
}

start_daemons() {
  local host
  host="$(hostname -s)"
  if ! alive "$state/munged.pid"; then
    munged --socket="$state/munge/munge.socket" --key-file="$state/munge/munge.key" \
      --pid-file="$state/munged.pid" --log-file="$state/log/munged.log" --seed-file="$state/munge/munge.seed"
  fi
  export SLURM_CONF="$conf"
  # In the foreground (-D) of a new session each: $! is the daemon, stopped by PID.
  if ! alive "$state/slurmctld.pid"; then
    setsid slurmctld -D -f "$conf" > "$state/log/slurmctld.out" 2>&1 < /dev/null &
    echo $! > "$state/slurmctld.pid"
  fi
  if ! alive "$state/slurmd.pid"; then
    setsid slurmd -D -N "$host" -f "$conf" > "$state/log/slurmd.out" 2>&1 < /dev/null &
    echo $! > "$state/slurmd.pid"
  fi
}

wait_idle() {
  local i s=""
  for i in $(seq 1 120); do
    s="$(SLURM_CONF="$conf" sinfo -h -o %T 2>/dev/null | head -n 1 || true)"
    case "$s" in idle|mixed|allocated) return 0 ;; esac
    for d in munged slurmctld slurmd; do
      alive "$state/$d.pid" || die "$d stopped; its log: $state/log/$d.log ($(tail -n 3 "$state/log/$d".* 2>/dev/null | tr '\n' ' '))"
    done
    sleep 0.25
  done
  die "the node is not idle after 30 s (sinfo: '$s'); logs in $state/log"
}

up() {
  require_tools
  write_config
  start_daemons
  wait_idle
  say "up: $(SLURM_CONF="$conf" sinfo -h -o '%P %D %c %T' | head -n 1) (state in $state)"
  echo "export SLURM_CONF=$conf"
}

stop_pid() {  # stop_pid NAME: SIGTERM the daemon of NAME.pid, SIGKILL after 10 s
  local f="$state/$1.pid" pid i
  alive "$f" || { rm -f "$f"; return 0; }
  pid="$(cat "$f")"
  kill "$pid" 2>/dev/null || true
  for i in $(seq 1 40); do kill -0 "$pid" 2>/dev/null || break; sleep 0.25; done
  if kill -0 "$pid" 2>/dev/null; then say "$1 ($pid) ignored SIGTERM: SIGKILL"; kill -9 "$pid" 2>/dev/null || true; fi
  rm -f "$f"
}

down() {
  [ -d "$state" ] || { say "nothing in $state"; return 0; }
  if alive "$state/slurmctld.pid"; then
    # Jobs first: a job's slurmstepd outlives slurmd otherwise.
    SLURM_CONF="$conf" scancel --full --quiet --user="$(id -un)" 2>/dev/null || true
    local i
    for i in $(seq 1 40); do
      [ -z "$(SLURM_CONF="$conf" squeue -h -o %i 2>/dev/null)" ] && break
      sleep 0.25
    done
  fi
  stop_pid slurmd
  stop_pid slurmctld
  stop_pid munged
  say "down ($state)"
}

status() {
  local d
  for d in munged slurmctld slurmd; do
    if alive "$state/$d.pid"; then echo "$d: running (pid $(cat "$state/$d.pid"))"; else echo "$d: stopped"; fi
  done
  if alive "$state/slurmctld.pid"; then
    SLURM_CONF="$conf" sinfo -o '%P %D %c %m %T'
    SLURM_CONF="$conf" squeue -o '%.8i %.30j %.10T %.10M %R'
  fi
  echo "export SLURM_CONF=$conf"
}

case "$cmd" in
  up) up ;;
  down) down ;;
  status) status ;;
  env) echo "export SLURM_CONF=$conf" ;;
  *) die "usage: $0 up|down|status|env [STATE_DIR]" ;;
esac
