#!/usr/bin/env bash
# A single-node SLURM cluster on this machine, for testing the SLURM profile (tests/workflow/test_slurm.py):
#
#   scripts/slurm-cluster.sh start DIR   # install (apt, as root) if needed, then start in DIR
#   export SLURM_CONF=DIR/etc/slurm.conf # sbatch, squeue, scancel ... now talk to it
#   scripts/slurm-cluster.sh stop DIR    # cancel its jobs, stop the daemons by PID, remove DIR
#
# Debian's slurmctld, slurmd, slurm-client and munge; no systemd, no accounting database.
# Everything but the apt install is written to DIR (a new, empty or missing folder): munged's
# key and socket (in a private folder, munged run as the munge user: DIR/munge, a link to a
# folder under /tmp that the munge user can reach), etc/slurm.conf, the state
# and spool folders, the logs and the daemons' PIDs (DIR/pids, one "name pid" a line). The node
# is this machine (`hostname -s` at 127.0.0.1) with its CPUs and memory; the ports are free ones.
#
# slurmd runs in a mount namespace of its own where DIR/etc is /etc/slurm: the SLURM executor
# plugin removes SLURM_CONF from the environment of the `srun` it runs inside each job, so
# there, as on a real cluster, Slurm's configuration must be at its default path.
set -euo pipefail

PACKAGES=(slurmctld slurmd slurm-client munge)

die() {
  echo "slurm-cluster: $*" >&2
  exit 1
}

# Exit status 3: SLURM cannot be installed or run on this machine (tests skip on it).
cannot_run_here() {
  echo "slurm-cluster: $*" >&2
  exit 3
}

install_packages() {
  local missing=()
  for package in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$package" 2>/dev/null | grep -q "ok installed" || missing+=("$package")
  done
  [[ ${#missing[@]} -eq 0 ]] && return 0
  [[ $(id -u) -eq 0 ]] || cannot_run_here "needs root to install ${missing[*]}"
  command -v apt-get >/dev/null 2>&1 || cannot_run_here "no apt-get to install ${missing[*]}"
  echo "slurm-cluster: installing ${missing[*]} with apt-get" >&2
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -q >/dev/null || cannot_run_here "apt-get update failed"
  apt-get install -y -q --no-install-recommends "${missing[@]}" >/dev/null \
    || cannot_run_here "apt-get install ${missing[*]} failed"
}

free_port() {
  python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'
}

# Waits up to $2 seconds for the command "${@:3}" to succeed; $1 names what is awaited.
wait_for() {
  local what=$1 seconds=$2
  shift 2
  for _ in $(seq $((seconds * 5))); do
    "$@" >/dev/null 2>&1 && return 0
    sleep 0.2
  done
  die "$what did not come up within ${seconds} s (logs in $DIR/log)"
}

# Starts "$@" in the background and records its PID under the name $1.
launch() {
  local name=$1
  shift
  "$@" >>"$DIR/log/$name.out" 2>&1 &
  echo "$name $!" >>"$DIR/pids"
}

write_slurm_conf() {
  local node cpus_and_memory
  node=$(hostname -s)
  # `slurmd -C` reports this machine's CPUs, sockets, cores and memory as slurm.conf expects them.
  cpus_and_memory=$(slurmd -C | head -n1 | sed 's/^NodeName=[^ ]* //')
  cat >"$DIR/etc/slurm.conf" <<EOF
ClusterName=lidarfield-test
SlurmctldHost=$node(127.0.0.1)
SlurmctldPort=$(free_port)
SlurmdPort=$(free_port)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$MUNGE_SOCKET
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool/%n
SlurmctldPidFile=$DIR/slurmctld.pid
SlurmdPidFile=$DIR/slurmd.pid
SlurmctldLogFile=$DIR/log/slurmctld.log
SlurmdLogFile=$DIR/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
MpiDefault=none
SwitchType=switch/none
PropagateResourceLimits=NONE
ReturnToService=2
# Finished jobs stay visible to squeue for 10 minutes: the profile's status command.
MinJobAge=600
NodeName=$node NodeAddr=127.0.0.1 $cpus_and_memory State=UNKNOWN
PartitionName=test Nodes=$node Default=YES MaxTime=INFINITE State=UP
EOF
}

start() {
  [[ $(id -u) -eq 0 ]] || cannot_run_here "must run as root (slurmd runs jobs as their users)"
  install_packages
  if [[ -e "$DIR" ]] && [[ -n "$(ls -A "$DIR")" ]]; then
    die "$DIR is not empty: stop that cluster first, or name a new folder"
  fi
  mkdir -p "$DIR"/{etc,log,state,spool}
  cp -a /etc/slurm/. "$DIR/etc/"
  DIR=$(cd "$DIR" && pwd)
  # munged runs as the munge user, who must reach its folder: DIR may lie in a folder only root
  # can enter (a test's tmp_path), so munged's private folder is made under /tmp and linked as
  # DIR/munge. Nobody else may list or write it; clients must reach the socket in it.
  local munge_dir
  munge_dir=$(mktemp -d /tmp/slurm-cluster-munge.XXXXXX)
  ln -s "$munge_dir" "$DIR/munge"
  chown munge:munge "$munge_dir"
  chmod 0711 "$munge_dir"
  MUNGE_SOCKET=$munge_dir/munge.socket
  setpriv --reuid=munge --regid=munge --init-groups mungekey --create --keyfile="$munge_dir/munge.key"
  launch munged setpriv --reuid=munge --regid=munge --init-groups munged --foreground \
    --key-file="$munge_dir/munge.key" --socket="$MUNGE_SOCKET" \
    --pid-file="$munge_dir/munged.pid" --log-file="$munge_dir/munged.log" \
    --seed-file="$munge_dir/munged.seed"
  wait_for munged 10 munge --socket="$MUNGE_SOCKET" --no-input

  write_slurm_conf
  export SLURM_CONF=$DIR/etc/slurm.conf
  launch slurmctld slurmctld -D -i -f "$SLURM_CONF"
  wait_for slurmctld 20 scontrol ping
  # unshare and sh exec into slurmd: the recorded PID is slurmd's.
  launch slurmd unshare --mount --propagation private sh -c \
    'mount --bind "$1" /etc/slurm && exec slurmd -D -f /etc/slurm/slurm.conf' sh "$DIR/etc"
  wait_for "the node" 30 bash -c "sinfo -h -N -o %t | grep -qx idle"
  echo "slurm-cluster: up in $DIR (export SLURM_CONF=$SLURM_CONF)" >&2
}

stop() {
  [[ -f "$DIR/pids" ]] || die "no cluster in $DIR (no $DIR/pids)"
  if [[ -f "$DIR/etc/slurm.conf" ]]; then
    # Cancel what still runs so no job step outlives the node.
    export SLURM_CONF=$DIR/etc/slurm.conf
    squeue -h -o %A 2>/dev/null | xargs -r scancel 2>/dev/null || true
    sleep 1
  fi
  # The daemons in the reverse order of their start, each by its recorded PID.
  tac "$DIR/pids" | while read -r name pid; do
    kill "$pid" 2>/dev/null || continue
    for _ in $(seq 50); do
      kill -0 "$pid" 2>/dev/null || break
      sleep 0.2
    done
    if kill -0 "$pid" 2>/dev/null; then
      echo "slurm-cluster: $name ($pid) ignored TERM, killing it" >&2
      kill -9 "$pid"
    fi
  done
  [[ -L "$DIR/munge" ]] && rm -rf "$(readlink "$DIR/munge")"
  rm -rf "$DIR"
  echo "slurm-cluster: stopped and removed $DIR" >&2
}

[[ $# -eq 2 ]] || die "usage: $0 start|stop DIR"
DIR=$2
case $1 in
  start) start ;;
  stop) stop ;;
  *) die "usage: $0 start|stop DIR" ;;
esac
