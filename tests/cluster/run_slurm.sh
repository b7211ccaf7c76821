#!/usr/bin/env bash
# Run the tiny twin through the SLURM profile on a one-node SLURM cluster started on this
# machine, check that its jobs went through sbatch (sacct), compare its tables with a local
# run, and shut the cluster down again.
#
#   sudo bash tests/cluster/run_slurm.sh            # needs root (apt-get, daemons)
#   KEEP_CLUSTER=1 bash tests/cluster/run_slurm.sh  # leave the daemons running afterwards
#   SMOKE=1 bash tests/cluster/run_slurm.sh         # only start the cluster and run one sbatch job
#
# What it starts: munged (authentication), MariaDB + slurmdbd (accounting, so that sacct
# works, as on a real cluster), slurmctld and one slurmd with this machine's CPUs. All
# state lives under $WORK (default /tmp/kitegully-slurm); nothing is installed as a service.
# Not part of `make test` (it needs root and takes minutes); run it by hand or in a CI job
# with root: `make slurm-test`.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT=$PWD
export PYTHONPATH="$ROOT/src${PYTHONPATH:+:$PYTHONPATH}"  # this checkout's library, also in a git worktree
WORK=${WORK:-/tmp/kitegully-slurm}
SITE_CONFIG=${SITE_CONFIG:-config/sites/tiny_twin.yaml}
SNAKEMAKE=${SNAKEMAKE:-$ROOT/.venv/bin/snakemake}
HOST=$(hostname -s)
CPUS=$(nproc)
MEM_MB=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 1024 ))

log() { echo "[run_slurm] $*"; }
die() { echo "[run_slurm] FAILED: $*" >&2; exit 1; }

[ "$(id -u)" = 0 ] || die "needs root (apt-get and the SLURM daemons); run with sudo"
[ -x "$SNAKEMAKE" ] || die "$SNAKEMAKE not found: run 'make venv' first"

# 1. Packages (Debian's slurm-wlm, munge, slurmdbd, MariaDB), installed only if missing.
need=()
for b in slurmctld:slurm-wlm slurmd:slurm-wlm munged:munge slurmdbd:slurmdbd mariadbd:mariadb-server; do
  command -v "${b%%:*}" >/dev/null 2>&1 || need+=("${b#*:}")
done
if [ ${#need[@]} -gt 0 ]; then
  log "installing ${need[*]}"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need[@]}" >/dev/null
fi

stop_pidfile() {  # stop the daemon whose pid file this script's config names, wait for it
  local f=$1 pid
  [ -f "$f" ] || return 0
  pid=$(cat "$f"); kill "$pid" 2>/dev/null || true
  for _ in $(seq 30); do kill -0 "$pid" 2>/dev/null || return 0; sleep 1; done
  echo "[run_slurm] WARNING: process $pid ($f) still running" >&2
}
cleanup() {
  local rc=$?
  if [ -z "${KEEP_CLUSTER:-}" ]; then
    log "stopping the cluster"
    for d in slurmd slurmctld slurmdbd; do stop_pidfile "$WORK/run/$d.pid"; done
    stop_pidfile "$WORK/mysqlrun/mysql.pid"
    [ -n "${MUNGE_STARTED:-}" ] && stop_pidfile /run/munge/munged.pid
    left=""
    for d in slurmd slurmctld slurmdbd mariadbd; do pgrep -x "$d" >/dev/null && left="$left $d"; done
    if [ -n "$left" ]; then log "daemons still running: $left"; [ $rc = 0 ] && rc=1; else log "daemons stopped"; fi
  fi
  log "total $((SECONDS / 60)) min $((SECONDS % 60)) s, exit $rc"
  exit $rc
}
trap cleanup EXIT

mkdir -p "$WORK"/{spool/ctld,spool/d,log,mysql,mysqlrun,run}
chmod 755 "$WORK"

# 2. munge: a fresh key for this throwaway cluster.
if ! pgrep -x munged >/dev/null; then
  mkdir -p /etc/munge /run/munge /var/log/munge /var/lib/munge
  [ -s /etc/munge/munge.key ] || dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key status=none
  chown -R munge:munge /etc/munge /run/munge /var/log/munge /var/lib/munge
  chmod 400 /etc/munge/munge.key
  runuser -u munge -- /usr/sbin/munged
  MUNGE_STARTED=1
fi
munge -n | unmunge >/dev/null || die "munge does not authenticate"

# 3. MariaDB for slurmdbd (accounting), in $WORK.
if [ ! -d "$WORK/mysql/mysql" ]; then
  mariadb-install-db --user=mysql --datadir="$WORK/mysql" >/dev/null
fi
chown -R mysql:mysql "$WORK/mysql" "$WORK/mysqlrun"
if ! mysqladmin --socket="$WORK/mysqlrun/mysql.sock" ping >/dev/null 2>&1; then
  mariadbd --user=mysql --datadir="$WORK/mysql" --socket="$WORK/mysqlrun/mysql.sock" \
    --skip-networking=0 --bind-address=127.0.0.1 --port=3307 --pid-file="$WORK/mysqlrun/mysql.pid" \
    > "$WORK/log/mysql.log" 2>&1 &
  for _ in $(seq 60); do mysqladmin --socket="$WORK/mysqlrun/mysql.sock" ping >/dev/null 2>&1 && break; sleep 1; done
fi
mysql --socket="$WORK/mysqlrun/mysql.sock" -e "CREATE DATABASE IF NOT EXISTS slurm_acct_db;
  CREATE USER IF NOT EXISTS 'slurm'@'localhost' IDENTIFIED BY 'kitegully';
  GRANT ALL ON slurm_acct_db.* TO 'slurm'@'localhost'; FLUSH PRIVILEGES;"

# 4. slurmdbd and slurm.conf: one node with this machine's CPUs, root as SlurmUser.
mkdir -p /etc/slurm
cat > /etc/slurm/slurmdbd.conf <<CONF
AuthType=auth/munge
DbdHost=localhost
SlurmUser=root
StorageType=accounting_storage/mysql
StorageHost=127.0.0.1
StoragePort=3307
StorageUser=slurm
StoragePass=kitegully
StorageLoc=slurm_acct_db
LogFile=$WORK/log/slurmdbd.log
PidFile=$WORK/run/slurmdbd.pid
CONF
chmod 600 /etc/slurm/slurmdbd.conf
cat > /etc/slurm/slurm.conf <<CONF
ClusterName=kitegully
SlurmctldHost=$HOST
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$WORK/spool/ctld
SlurmdSpoolDir=$WORK/spool/d
SlurmctldPidFile=$WORK/run/slurmctld.pid
SlurmdPidFile=$WORK/run/slurmd.pid
SlurmctldLogFile=$WORK/log/slurmctld.log
SlurmdLogFile=$WORK/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU_Memory
ReturnToService=2
MinJobAge=600
AccountingStorageType=accounting_storage/slurmdbd
AccountingStorageHost=localhost
JobAcctGatherType=jobacct_gather/linux
JobCompType=jobcomp/none
NodeName=$HOST CPUs=$CPUS RealMemory=$MEM_MB State=UNKNOWN
PartitionName=normal Nodes=$HOST Default=YES MaxTime=INFINITE State=UP
CONF
pgrep -x slurmdbd >/dev/null || /usr/sbin/slurmdbd
for _ in $(seq 30); do sacctmgr -n list cluster >/dev/null 2>&1 && break; sleep 1; done
sacctmgr -i add cluster kitegully >/dev/null 2>&1 || true
sacctmgr -i add account kitegully Cluster=kitegully Description=kitegully Organization=kitegully >/dev/null 2>&1 || true
# root's default account, so the plugin finds it without --default-resources slurm_account=...
# (a --default-resources on the command line would replace the profile's defaults).
sacctmgr -i add user root Account=kitegully DefaultAccount=kitegully >/dev/null 2>&1 || true
pgrep -x slurmctld >/dev/null || /usr/sbin/slurmctld
pgrep -x slurmd >/dev/null || /usr/sbin/slurmd
for _ in $(seq 60); do sinfo -h -o %T 2>/dev/null | grep -qE '^(idle|mixed)' && break; sleep 1; done
sinfo -h -o %T | grep -qE '^(idle|mixed)' || die "the SLURM node did not come up (see $WORK/log)"
log "cluster up: $(sinfo -h -o '%P %D %c %T')"

if [ -n "${SMOKE:-}" ]; then
  # Only check the cluster: one sbatch job, seen COMPLETED by sacct.
  jid=$(sbatch --parsable -A kitegully -p normal --wrap "hostname; sleep 1" -o "$WORK/log/smoke_%j.out")
  for _ in $(seq 60); do sacct -X -n -P -j "$jid" -o State | grep -q COMPLETED && break; sleep 1; done
  sacct -X -n -P -j "$jid" -o State | grep -q COMPLETED || die "smoke job $jid did not complete: $(sacct -X -n -P -j "$jid" -o State)"
  log "SMOKE PASSED: job $jid completed and is in sacct"
  exit 0
fi

# 5. The tiny twin through the profile, then locally, into separate results folders.
START=$(date +%Y-%m-%dT%H:%M:%S)
SLURM_RESULTS=$WORK/results_slurm
LOCAL_RESULTS=$WORK/results_local
rm -rf "$SLURM_RESULTS" "$LOCAL_RESULTS"
log "running $SITE_CONFIG through workflow/profiles/slurm"
t0=$SECONDS
"$SNAKEMAKE" --profile workflow/profiles/slurm --configfile "$SITE_CONFIG" \
  --config results_dir="$SLURM_RESULTS" > "$WORK/log/snakemake_slurm.log" 2>&1 || { tail -30 "$WORK/log/snakemake_slurm.log"; die "the SLURM run failed"; }
t_slurm=$((SECONDS - t0))
log "SLURM run: $t_slurm s"
log "running $SITE_CONFIG locally"
t0=$SECONDS
"$SNAKEMAKE" --cores "$CPUS" --configfile "$SITE_CONFIG" --config results_dir="$LOCAL_RESULTS" \
  > "$WORK/log/snakemake_local.log" 2>&1 || { tail -30 "$WORK/log/snakemake_local.log"; die "the local run failed"; }
t_local=$((SECONDS - t0))
log "local run: $t_local s"

# 6. Jobs went through sbatch: sacct lists one completed job per Snakemake job.
n_jobs=$(grep -cE "^(localrule|rule) " "$WORK/log/snakemake_slurm.log" || true)
n_local=$(grep -cE "^localrule " "$WORK/log/snakemake_slurm.log" || true)
n_sacct=$(sacct -X -n -P -S "$START" -o JobID,JobName,State | grep -c "|COMPLETED" || true)
log "snakemake jobs: $n_jobs ($n_local local rules), sacct COMPLETED jobs: $n_sacct"
[ "$n_sacct" -ge $(( n_jobs - n_local )) ] && [ "$n_sacct" -gt 0 ] || die "sacct shows $n_sacct completed jobs for $((n_jobs - n_local)) submitted"
sacct -X -S "$START" -o JobID,JobName%40,State,Elapsed,AllocCPUS,MaxRSS > "$WORK/sacct.txt"

# 7. Same tables from both runs.
site=$(awk '/^  name:/ {print $2; exit}' "$SITE_CONFIG")
"$ROOT/.venv/bin/python" benchmarks/compare_runs.py "$LOCAL_RESULTS/$site" "$SLURM_RESULTS/$site" \
  || die "tables of the SLURM and the local run differ"
log "PASSED: $n_sacct SLURM jobs, identical tables (sacct listing in $WORK/sacct.txt)"
