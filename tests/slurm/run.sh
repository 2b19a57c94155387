#!/usr/bin/env bash
# The sample job under a real single-node Slurm: a 4-task array and its merge, submitted with
# `errmap slurm --submit`, then the same job unsharded for comparison (done by tests/slurm.rs).
#   tests/slurm/run.sh ERRMAP WORKDIR
# Leaves WORKDIR/sharded (shards + reduce) and WORKDIR/single (one run). Needs root (the test
# cluster runs its daemons as root) and the Debian packages slurm-wlm and munge.
set -euo pipefail
errmap=${1:?errmap binary} work=${2:?work folder}
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
mkdir -p "$work"
work=$(cd "$work" && pwd)
trap '"$here/cluster.sh" stop "$work/cluster"' EXIT
eval "$("$here/cluster.sh" start "$work/cluster")"
export SLURM_CONF

# The sample family with few epochs: the CI machine has 2 cores.
rm -rf "$work/data"
cp -r "$repo/data/web-plate" "$work/data"
sed -i 's/^epochs = .*/epochs = 40/' "$work/data/job.toml"
cd "$work"

read -r array_id merge_id < <("$errmap" slurm data/job.toml --shards 4 --backend cpu --out-dir sharded --submit --quiet)
echo "slurm: array job $array_id, merge job $merge_id"
for _ in $(seq 600); do
    if [ -z "$(squeue -h -j "$array_id,$merge_id" 2>/dev/null)" ]; then break; fi
    sleep 1
done
state=$(scontrol show job "$merge_id" 2>/dev/null | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p' | head -n 1)
echo "slurm: merge job $merge_id ended $state"
if [ ! -s sharded/run.json ]; then
    echo "slurm: the merge committed no run; logs:" >&2
    tail -n 30 sharded/slurm/*.log "$work/cluster/slurmctld.log" >&2 || true
    exit 1
fi
"$errmap" batch data/job.toml --backend cpu --out-dir single --quiet >/dev/null
