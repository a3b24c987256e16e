#!/usr/bin/env bash
# A single-node SLURM on this machine, to run the workflow through
# `snakemake --profile profiles/slurm` exactly as on a cluster (issue 13).
#
#   bash scripts/slurm-local.sh start   # install (Debian packages), configure, start, wait
#   bash scripts/slurm-local.sh stop    # stop every daemon it started
#   bash scripts/slurm-local.sh status  # sinfo
#
# Needs root and Debian's package registry (apt). Starts munged, MariaDB,
# slurmdbd (accounting: the Snakemake SLURM plugin asks sacct for job
# states), slurmctld and slurmd; one node with this machine's cores and
# memory, one partition `local`, one account `colourhs`. Process tracking
# without cgroups (proctrack/linuxproc), so it runs in a container too.
# Nothing here is needed on a real cluster: there, only the profile's
# account and partition are set.
set -euo pipefail

CLUSTER=colourhs
ACCOUNT=colourhs
PARTITION=local
CONF=/etc/slurm
STATE=/var/lib/colourhs-slurm
DB_PASS=colourhs-local

log() { echo "slurm-local: $*" >&2; }

install() {
  local missing=()
  for cmd in slurmctld slurmd slurmdbd munged mariadbd sacct; do
    command -v "$cmd" > /dev/null || missing+=("$cmd")
  done
  if ((${#missing[@]})); then
    log "installing slurm-wlm, slurmdbd, munge and mariadb-server (missing: ${missing[*]})"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends slurm-wlm slurmdbd munge mariadb-server > /dev/null
  fi
}

configure() {
  local host cpus mem
  host=$(hostname -s)
  cpus=$(nproc)
  mem=$(($(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 1024)) # MB, 1 GB for the system
  mkdir -p "$CONF" "$STATE"/{ctld,d,log} /run/munge /var/log/munge
  cat > "$CONF/slurm.conf" << EOF
ClusterName=$CLUSTER
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
SchedulerType=sched/backfill
StateSaveLocation=$STATE/ctld
SlurmdSpoolDir=$STATE/d
SlurmctldPidFile=$STATE/slurmctld.pid
SlurmdPidFile=$STATE/slurmd.pid
SlurmctldLogFile=$STATE/log/slurmctld.log
SlurmdLogFile=$STATE/log/slurmd.log
AccountingStorageType=accounting_storage/slurmdbd
AccountingStorageHost=localhost
AccountingStorageEnforce=associations
JobAcctGatherType=jobacct_gather/linux
JobCompType=jobcomp/none
MinJobAge=300
NodeName=$host CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=$PARTITION Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
  cat > "$CONF/slurmdbd.conf" << EOF
AuthType=auth/munge
DbdHost=localhost
SlurmUser=root
PidFile=$STATE/slurmdbd.pid
LogFile=$STATE/log/slurmdbd.log
StorageType=accounting_storage/mysql
StorageHost=localhost
StorageUser=slurm
StoragePass=$DB_PASS
StorageLoc=slurm_acct_db
EOF
  chmod 600 "$CONF/slurmdbd.conf"
  if [ ! -s /etc/munge/munge.key ]; then
    dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
  fi
  chown -R munge:munge /etc/munge /run/munge /var/log/munge /var/lib/munge 2> /dev/null || true
  chmod 400 /etc/munge/munge.key
}

wait_for() { # seconds, description, command...
  local n=$1 what=$2
  shift 2
  for _ in $(seq "$n"); do
    if "$@" > /dev/null 2>&1; then return 0; fi
    sleep 1
  done
  log "timed out waiting for $what"
  return 1
}

start() {
  install
  configure
  pgrep -x munged > /dev/null || runuser -u munge -- /usr/sbin/munged
  wait_for 20 munged munge -n
  if ! pgrep -x mariadbd > /dev/null; then
    mkdir -p /run/mysqld && chown mysql:mysql /run/mysqld
    (mysqld_safe --user=mysql > "$STATE/log/mariadb.log" 2>&1 &)
  fi
  wait_for 60 MariaDB mysqladmin ping
  mysql -u root << EOF
CREATE DATABASE IF NOT EXISTS slurm_acct_db;
CREATE USER IF NOT EXISTS 'slurm'@'localhost' IDENTIFIED BY '$DB_PASS';
GRANT ALL ON slurm_acct_db.* TO 'slurm'@'localhost';
FLUSH PRIVILEGES;
EOF
  pgrep -x slurmdbd > /dev/null || slurmdbd
  wait_for 60 slurmdbd sacctmgr -n show cluster
  sacctmgr -i -Q add cluster "$CLUSTER" > /dev/null 2>&1 || true
  sacctmgr -i -Q add account "$ACCOUNT" cluster="$CLUSTER" > /dev/null 2>&1 || true
  sacctmgr -i -Q add user root account="$ACCOUNT" cluster="$CLUSTER" > /dev/null 2>&1 || true
  pgrep -x slurmctld > /dev/null || slurmctld
  wait_for 60 slurmctld scontrol ping
  pgrep -x slurmd > /dev/null || slurmd
  wait_for 90 "the node to be idle" bash -c "sinfo -h -o %T | grep -qx idle"
  sinfo
  log "running: account $ACCOUNT, partition $PARTITION (snakemake --profile profiles/slurm" \
    "--default-resources slurm_account=$ACCOUNT slurm_partition=$PARTITION)"
}

stop() {
  scontrol shutdown > /dev/null 2>&1 || true
  pkill -x slurmd || true
  pkill -x slurmctld || true
  pkill -x slurmdbd || true
  mysqladmin shutdown > /dev/null 2>&1 || true
  pkill -x munged || true
  log "stopped"
}

case "${1:-}" in
  start) start ;;
  stop) stop ;;
  status) sinfo ;;
  *)
    echo "usage: $0 start|stop|status" >&2
    exit 2
    ;;
esac
