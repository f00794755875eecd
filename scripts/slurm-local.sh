#!/usr/bin/env bash
# A single-node Slurm on this machine for `hirad study --slurm` (issue 25): Debian's slurm-wlm
# and munge; munged, slurmctld and slurmd (2 CPUs, niced) with their configuration, state and
# logs in $HIRAD_SLURM_DIR (default /tmp/hirad-slurm). With HIRAD_SLURM_ACCOUNTING=1 also
# slurmdbd on a private MariaDB, so that `sacct` answers. Commands:
#   all (default)  install, start (with accounting), run the cornell study through Slurm and
#                  compare it with an in-process run (cargo test -p hirad-cli --test slurm), stop
#   install        apt-get the packages when missing (root or sudo)
#   start          start the daemons that are not running; prints `export SLURM_CONF=…`
#   run            the test above against the running daemons
#   stop           stop the daemons this script started (by their pid files)
# Needs root (slurmd runs jobs as their user). Tools reach this Slurm through SLURM_CONF.
set -euo pipefail
cd "$(dirname "$0")/.."
D=${HIRAD_SLURM_DIR:-/tmp/hirad-slurm}
export SLURM_CONF="$D/slurm.conf"
SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
ACCT=${HIRAD_SLURM_ACCOUNTING:-0}

install_pkgs() {
  local need=()
  local pkgs=(slurm-wlm munge)
  [ "$ACCT" = 1 ] && pkgs+=(slurmdbd mariadb-server)
  for p in "${pkgs[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || need+=("$p"); done
  if [ ${#need[@]} -gt 0 ]; then
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${need[@]}"
  fi
}

conf() {
  local host mem
  host=$(hostname -s)
  mem=$(awk '/MemTotal/ {print int($2 / 1024 / 2)}' /proc/meminfo)
  mkdir -p "$D/state" "$D/spool" "$D/log"
  cat > "$SLURM_CONF" <<EOF
ClusterName=hirad-local
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$D/state
SlurmdSpoolDir=$D/spool
SlurmctldPidFile=$D/slurmctld.pid
SlurmdPidFile=$D/slurmd.pid
SlurmctldLogFile=$D/log/slurmctld.log
SlurmdLogFile=$D/log/slurmd.log
ProctrackType=proctrack/pgid
TaskPlugin=task/none
MpiDefault=none
ReturnToService=2
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MinJobAge=600
$(if [ "$ACCT" = 1 ]; then
  printf '%s\n' AccountingStorageType=accounting_storage/slurmdbd AccountingStorageHost=127.0.0.1 \
    JobAcctGatherType=jobacct_gather/linux
else
  echo JobAcctGatherType=jobacct_gather/none
fi)
NodeName=$host NodeAddr=127.0.0.1 CPUs=2 RealMemory=$mem State=UNKNOWN
PartitionName=local Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
}

alive() { [ -f "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null; }

# slurmdbd on a MariaDB of its own (data in $D/db, 127.0.0.1:3307).
accounting() {
  if ! alive "$D/mariadbd.pid"; then
    [ -d "$D/db/mysql" ] || mariadb-install-db --datadir="$D/db" --user=root \
      --auth-root-authentication-method=socket >"$D/log/mariadb-install.log" 2>&1
    nice -n 10 mariadbd --datadir="$D/db" --socket="$D/db.sock" --port=3307 \
      --bind-address=127.0.0.1 --user=root --pid-file="$D/mariadbd.pid" \
      --log-error="$D/log/mariadb.log" &
    for _ in $(seq 60); do mariadb -S "$D/db.sock" -e 'select 1' >/dev/null 2>&1 && break; sleep 0.5; done
    mariadb -S "$D/db.sock" -e "CREATE USER IF NOT EXISTS 'slurm'@'127.0.0.1' IDENTIFIED BY 'hirad-local';
      GRANT ALL ON slurm_acct_db.* TO 'slurm'@'127.0.0.1';"
  fi
  cat > "$D/slurmdbd.conf" <<EOF
AuthType=auth/munge
DbdHost=localhost
DbdAddr=127.0.0.1
SlurmUser=root
PidFile=$D/slurmdbd.pid
LogFile=$D/log/slurmdbd.log
StorageType=accounting_storage/mysql
StorageHost=127.0.0.1
StoragePort=3307
StorageUser=slurm
StoragePass=hirad-local
StorageLoc=slurm_acct_db
EOF
  chmod 600 "$D/slurmdbd.conf"
  alive "$D/slurmdbd.pid" || nice -n 10 slurmdbd
  for _ in $(seq 60); do sacctmgr -n list cluster >/dev/null 2>&1 && break; sleep 0.5; done
  sacctmgr -i add cluster hirad-local >/dev/null 2>&1 || true
}

start() {
  mkdir -p "$D"
  conf
  # munge: reuse a running munged, else start one (its pid file marks it as ours).
  if ! munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
    $SUDO install -d -o munge -g munge -m 0755 /run/munge
    $SUDO runuser -u munge -- /usr/sbin/munged
    cp /run/munge/munged.pid "$D/munged.pid"
  fi
  if [ "$ACCT" = 1 ]; then accounting; fi
  alive "$D/slurmctld.pid" || $SUDO nice -n 10 slurmctld
  alive "$D/slurmd.pid" || $SUDO nice -n 19 slurmd
  for _ in $(seq 60); do
    if sinfo -h -o %T 2>/dev/null | grep -qx idle; then
      sinfo
      echo "export SLURM_CONF=$SLURM_CONF"
      return 0
    fi
    scontrol update nodename="$(hostname -s)" state=resume >/dev/null 2>&1 || true
    sleep 1
  done
  echo "Slurm did not come up; logs in $D/log" >&2
  tail -5 "$D"/log/*.log >&2 || true
  return 1
}

stop() {
  for d in slurmd slurmctld slurmdbd mariadbd munged; do
    if alive "$D/$d.pid"; then
      local pid
      pid=$(cat "$D/$d.pid")
      $SUDO kill "$pid"
      for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    fi
    rm -f "$D/$d.pid"
  done
}

run() {
  nice -n 10 cargo test --release -p hirad-cli --test slurm -- --nocapture --test-threads 1
}

cmd=${1:-all}
case "$cmd" in
  install) install_pkgs ;;
  start) start ;;
  stop) stop ;;
  run) run ;;
  all)
    t0=$(date +%s)
    ACCT=${HIRAD_SLURM_ACCOUNTING:-1}
    install_pkgs
    trap stop EXIT
    start
    run
    echo "slurm-local.sh all: $(( $(date +%s) - t0 )) s including the install"
    ;;
  *) echo "usage: $0 [all|install|start|run|stop]" >&2; exit 2 ;;
esac
