"""Run under ``mpiexec -n 2``: checks that all-reduced DDPG updates keep the ranks identical.

Usage: mpiexec -n 2 python gradient_sync.py {sum|mean} RESULT.json

Each rank starts from different weights and learns from different data. After the broadcast
and several updates, rank 0 writes what it found to RESULT.json.
"""

import json
import sys

import numpy as np
import torch

from dlo_course import mpi
from dlo_course.config import DDPGConfig
from dlo_course.ddpg import DDPG

op, result_path = sys.argv[1], sys.argv[2]
torch.set_num_threads(1)
rank, n = mpi.rank(), mpi.size()

torch.manual_seed(100 + rank)  # deliberately different initial weights on each rank
agent = DDPG(5, 2, -1.0, 1.0, DDPGConfig(hidden_sizes=(16, 16), batch_size=8))
nets = (agent.actor, agent.critic, agent.actor_target, agent.critic_target)
differ_at_start = not mpi.modules_in_sync(*nets)
mpi.broadcast_module(agent.actor)
mpi.broadcast_module(agent.critic)
agent.sync_targets()
same_after_broadcast = mpi.modules_in_sync(*nets)

# Record each gradient before and after the reduction: the one after is the one applied.
local_grads, applied_grads = [], []


def recording_reducer(module):
    local_grads.append([p.grad.clone().numpy() for p in module.parameters()])
    mpi.allreduce_gradients(module, op=op)
    applied_grads.append([p.grad.clone().numpy() for p in module.parameters()])


rng = np.random.default_rng(rank)  # different data on each rank
for _ in range(5):
    batch = {"obs": rng.normal(size=(8, 5)), "act": rng.uniform(-1, 1, (8, 2)),
             "rew": rng.normal(size=8), "next_obs": rng.normal(size=(8, 5)),
             "done": np.zeros(8)}
    agent.update(batch, recording_reducer)

everyone_local = mpi.allgather(local_grads)  # [rank][call][parameter]
applied_is_reduction, local_grads_differ = True, False
for call, applied in enumerate(applied_grads):
    for i, g in enumerate(applied):
        expected = sum(everyone_local[r][call][i] for r in range(n))
        if op == "mean":
            expected = expected / np.float32(n)
        applied_is_reduction &= bool(np.array_equal(g, expected))
        local_grads_differ |= not np.array_equal(everyone_local[0][call][i],
                                                 everyone_local[1][call][i])

result = {
    "size": n,
    "differ_at_start": differ_at_start,
    "same_after_broadcast": same_after_broadcast,
    "local_grads_differ": local_grads_differ,
    "applied_is_reduction": applied_is_reduction,
    "same_after_updates": mpi.modules_in_sync(*nets),
    "reduced_calls": len(applied_grads),
}
if mpi.is_root():
    with open(result_path, "w") as f:
        json.dump(result, f)
