# A single-node Slurm cluster on loopback for tests and benchmarks, started and stopped by pid.
# Source it, then:
#   slurm_cluster_available || skip ...   (are munged, slurmctld, slurmd, sbatch installed?)
#   slurm_cluster_start DIR               (everything in DIR; exports SLURM_CONF)
#   slurm_cluster_stop                    (kills only the daemons it started; also on EXIT)
# munged runs with its own key, socket, pid, log and seed files in DIR; slurm.conf puts the
# controller and the one node on 127.0.0.1 (SlurmctldHost=localhost(127.0.0.1), NodeAddr=127.0.0.1,
# slurmd -N localhost) with the machine's real CPUs and memory and ports free on this machine.
# Must run as root (slurmd starts the jobs as their user).

slurm_cluster_pids=()

slurm_cluster_available() {
  local p
  for p in munged slurmctld slurmd sbatch squeue scancel sinfo; do
    command -v "$p" >/dev/null 2>&1 || { slurm_cluster_missing="$p"; return 1; }
  done
  return 0
}

# A TCP port nobody uses (and the next one too), from /proc/net/tcp{,6} (no iproute2 needed).
slurm_cluster_free_port() {
  local port used
  used=$(awk 'NR > 1 {split($2, a, ":"); print a[2]}' /proc/net/tcp /proc/net/tcp6 2>/dev/null | sort -u)
  for _ in $(seq 1 50); do
    port=$((20000 + RANDOM % 20000))
    if ! grep -qiE "^($(printf %04X $port)|$(printf %04X $((port + 1))))$" <<<"$used"; then
      echo "$port"; return 0
    fi
  done
  return 1
}

slurm_cluster_stop() {
  local pid i
  # Reverse order: slurmd, slurmctld, munged.
  for ((i = ${#slurm_cluster_pids[@]} - 1; i >= 0; i--)); do
    pid="${slurm_cluster_pids[$i]}"
    kill "$pid" 2>/dev/null
  done
  for pid in "${slurm_cluster_pids[@]}"; do
    for _ in $(seq 1 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -9 "$pid" 2>/dev/null
  done
  slurm_cluster_pids=()
}

slurm_cluster_start() {
  local dir="$1"
  [ "$(id -u)" = 0 ] || { echo "slurm_cluster: must run as root (slurmd)" >&2; return 1; }
  rm -rf "$dir"; mkdir -p "$dir"/{munge,state,spool,log}
  chmod 700 "$dir" "$dir/munge"
  trap slurm_cluster_stop EXIT

  # munge: a fresh key; munged with every path in DIR (never the system's daemon).
  dd if=/dev/urandom of="$dir/munge/munge.key" bs=1024 count=1 status=none
  chmod 400 "$dir/munge/munge.key"
  munged --key-file="$dir/munge/munge.key" --socket="$dir/munge/munge.socket" \
    --pid-file="$dir/munge/munged.pid" --log-file="$dir/munge/munged.log" \
    --seed-file="$dir/munge/munged.seed" --foreground --force >"$dir/log/munged.out" 2>&1 &
  slurm_cluster_pids+=($!)
  for _ in $(seq 1 50); do [ -S "$dir/munge/munge.socket" ] && break; sleep 0.1; done
  [ -S "$dir/munge/munge.socket" ] || { echo "slurm_cluster: munged did not start:" >&2; cat "$dir/log/munged.out" "$dir/munge/munged.log" >&2; return 1; }

  # The node as slurmd sees it (CPUs, sockets, cores, threads, memory).
  local hw cpus sockets cores threads mem port
  hw=$(slurmd -C 2>/dev/null | head -n 1)
  cpus=$(sed -n 's/.*CPUs=\([0-9]*\).*/\1/p' <<<"$hw"); cpus=${cpus:-$(nproc)}
  sockets=$(sed -n 's/.*SocketsPerBoard=\([0-9]*\).*/\1/p' <<<"$hw"); sockets=${sockets:-1}
  cores=$(sed -n 's/.*CoresPerSocket=\([0-9]*\).*/\1/p' <<<"$hw"); cores=${cores:-$cpus}
  threads=$(sed -n 's/.*ThreadsPerCore=\([0-9]*\).*/\1/p' <<<"$hw"); threads=${threads:-1}
  mem=$(sed -n 's/.*RealMemory=\([0-9]*\).*/\1/p' <<<"$hw"); mem=${mem:-1024}
  port=$(slurm_cluster_free_port) || { echo "slurm_cluster: no free port" >&2; return 1; }
  slurm_cluster_cpus="$cpus"

  cat >"$dir/slurm.conf" <<CONF
ClusterName=previztest
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$dir/munge/munge.socket
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
SchedulerParameters=sched_interval=1
MpiDefault=none
ReturnToService=2
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MinJobAge=600
KillWait=5
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
NodeName=localhost NodeAddr=127.0.0.1 CPUs=$cpus Sockets=$sockets CoresPerSocket=$cores ThreadsPerCore=$threads RealMemory=$mem State=UNKNOWN
PartitionName=batch Nodes=localhost Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO
CONF
  export SLURM_CONF="$dir/slurm.conf"

  slurmctld -D -c -f "$SLURM_CONF" >"$dir/log/slurmctld.out" 2>&1 &
  slurm_cluster_pids+=($!)
  slurmd -D -N localhost -f "$SLURM_CONF" >"$dir/log/slurmd.out" 2>&1 &
  slurm_cluster_pids+=($!)

  # Ready when the node is idle.
  local state=""
  for _ in $(seq 1 150); do
    state=$(sinfo -h -n localhost -o '%T' 2>/dev/null | head -n 1)
    [ "$state" = idle ] && return 0
    sleep 0.2
  done
  echo "slurm_cluster: node not idle after 30 s (state '$state'); logs:" >&2
  tail -n 20 "$dir/log/slurmctld.log" "$dir/log/slurmd.log" "$dir/log/"*.out >&2 2>/dev/null
  return 1
}
