"""The mutation suite (issue 13): for every exercise, plausible wrong answers (the solution
with one mistake a student could make) must score 0, and the solution full marks. A few
mutants break only an exercise's secondary requirement and must get exactly its partial
credit. A written answer's mutants that are there and long enough, wrong or vacuous, earn
nothing either, but await the instructor's review (:data:`AWAITS`): no pattern gives a
written answer points (issue 51).

Round k grades, with the real grader in a pytest subprocess, a class of one student whose
every solution notebook carries, in each exercise that has one, its k-th mutant: one grading
per round (six) instead of one per lesson and round, since each grading starts pytest and the
sandbox's preloaded libraries (about 9 s of CPU) whatever it grades. One lesson's mutants run
alone with ``pytest tests/test_mutations.py --mutants-of 04_ddpg``. (An exercise that uses an
earlier answer gets that answer's mutant too: its own mutant must score 0 all the same.)
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

from dlo_course.grading import notebooks
from dlo_course.grading.grade import grading_command
from test_rubric import VACUOUS, WRONG_ANSWERS  # long answers, wrong or vacuous

REPO = Path(__file__).resolve().parents[1]
SOLUTIONS = REPO / "solutions"

# ddpg_update's critic and actor steps, as the solution writes them (a mutant swaps them)
_CRITIC_STEP = ("    loss_q = ((agent.critic(obs, act) - q_target) ** 2).mean()\n"
                "    agent.critic_optimizer.zero_grad()\n    loss_q.backward()\n"
                "    agent.critic_optimizer.step()\n")
_ACTOR_STEP = ("    # 3. Actor step on the freshly updated critic; frozen, the critic gets no "
               "gradient from it.\n    agent.critic.requires_grad_(False)\n"
               "    loss_pi = -agent.critic(obs, agent.actor(obs)).mean()\n"
               "    agent.actor_optimizer.zero_grad()\n    loss_pi.backward()\n"
               "    agent.actor_optimizer.step()\n    agent.critic.requires_grad_(True)\n")

# sum_gradients_over_ranks from the packing to the unpacking
_ALLREDUCE = ("    flat = torch.cat([p.grad.reshape(-1) for p in params]).numpy()  # (n,) float32\n"
              "    total = np.empty_like(flat)\n"
              "    comm.Allreduce(flat, total)  # MPI's default operation is the sum\n"
              "    offset = 0\n    for p in params:\n        k = p.numel()\n"
              "        p.grad.copy_(torch.from_numpy(total[offset:offset + k]).view_as(p))\n")

# a written answer's mutants replace the whole answer (the cell but its first-line comment)
WHOLE_ANSWER = "<the whole answer>"
AWAITS = "awaiting review"  # expected of a long written answer: no points, all of them pending

# exercise -> [(the mistake, text of the solution, replaced by[, points expected])]
MUTANTS: dict[str, list[tuple]] = {
    "discounted_return": [
        ("no discount", "float(r) + gamma * total", "float(r) + total"),
        ("discounts the wrong end", "reversed(list(rewards))", "list(rewards)")],
    "bellman_target": [
        ("missing done mask", "gamma * next_q * (1.0 - done)", "gamma * next_q"),
        ("inverted done mask", "(1.0 - done)", "done")],
    "q_iteration_sweep": [
        ("min for max", "np.max(q, axis=1)", "np.min(q, axis=1)"),
        ("missing done mask", "gamma * best_next * (1.0 - done)", "gamma * best_next"),
        ("value of the current state", "np.max(q, axis=1)[next_state]", "np.max(q, axis=1)[:, None]")],
    "prediction_seeds": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "They will overlap, I think."),
        ("an outcome, long, with no reason from the interval's width", WHOLE_ANSWER,
         WRONG_ANSWERS["prediction_seeds"][0], AWAITS)],
    "prediction_sweeps": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "Five sweeps, I think."),
        ("issue 51's vacuous sentence (a digit and 'as')", WHOLE_ANSWER, VACUOUS, AWAITS)],
    "RingBuffer": [
        ("off-by-one size", "min(self._size + 1, self.capacity)", "min(self._size + 1, self.capacity - 1)"),
        ("samples empty rows", "self.rng.integers(0, self._size,", "self.rng.integers(0, self.capacity,"),
        ("global generator", "self.rng.integers(0, self._size, size=batch_size)",
         "np.random.randint(0, self._size, size=batch_size)"),
        ("done on truncation too", "self.done[i] = float(terminated)",
         "self.done[i] = float(terminated or truncated)"),
        ("truncation for termination", "self.done[i] = float(terminated)",
         "self.done[i] = float(truncated)")],
    "prediction_ring": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "Rewards 5, 6, 7, 3, 4.")],
    "build_mlp": [
        ("missing ReLU", "layers += [nn.Linear(width, h), nn.ReLU()]", "layers += [nn.Linear(width, h)]"),
        ("default output initialisation", "    nn.init.uniform_(out.weight, -final_init, final_init)\n"
         "    nn.init.uniform_(out.bias, -final_init, final_init)\n", ""),
        ("Tanh for ReLU", "nn.ReLU()", "nn.Tanh()")],
    "squash_action": [
        ("scale and centre swapped", "bias + scale * torch.tanh(raw)", "scale + bias * torch.tanh(raw)"),
        ("clamp for tanh", "torch.tanh(raw)", "torch.clamp(raw, -1, 1)")],
    "Critic": [
        ("action before observation", "torch.cat([obs, act], dim=-1)", "torch.cat([act, obs], dim=-1)"),
        ("squeezed output", "self.net(torch.cat([obs, act], dim=-1))",
         "self.net(torch.cat([obs, act], dim=-1)).squeeze(-1)"),
        ("action detached: no dQ/da for the actor", "torch.cat([obs, act], dim=-1)",
         "torch.cat([obs, act.detach()], dim=-1)"),
        ("network on the observation alone", "build_mlp(obs_dim + act_dim,", "build_mlp(obs_dim,")],
    "prediction_parameters": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "About 140 000.")],
    "parameter_counts": [
        ("forgets the biases", "total += (width + 1) * h", "total += width * h"),
        ("critic without the action", "count(obs_dim + act_dim, 1)", "count(obs_dim, 1)")],
    "critic_loss": [
        ("sum for mean", "** 2).mean()", "** 2).sum()"),
        ("absolute error", "((q - q_target) ** 2).mean()", "(q - q_target).abs().mean()"),
        ("F.mse_loss, no shape check (secondary requirement only)",
         "    if q.shape != q_target.shape:\n        raise ValueError(f\"q {tuple(q.shape)} and "
         "q_target {tuple(q_target.shape)} differ\")\n    return ((q - q_target) ** 2).mean()",
         "    return torch.nn.functional.mse_loss(q, q_target)", 1.5)],
    "polyak_update": [
        ("swapped Polyak factors", "w_target.mul_(1.0 - tau).add_(w, alpha=tau)",
         "w_target.mul_(tau).add_(w, alpha=1.0 - tau)"),
        ("hard update", "w_target.mul_(1.0 - tau).add_(w, alpha=tau)", "w_target.copy_(w)")],
    "ddpg_update": [
        ("critic not frozen during the actor step", "    agent.critic.requires_grad_(False)\n", ""),
        ("actor step before the critic step", _CRITIC_STEP + "\n" + _ACTOR_STEP,
         _ACTOR_STEP.split("\n", 1)[1] + "\n" + _CRITIC_STEP),
        ("Polyak on the actor's target only",
         "((agent.actor_target, agent.actor), (agent.critic_target, agent.critic))",
         "((agent.actor_target, agent.actor),)"),
        ("trained networks, not the targets, in the Bellman target",
         "agent.critic_target(next_obs, agent.actor_target(next_obs))",
         "agent.critic(next_obs, agent.actor(next_obs))"),
        ("policy loss with the wrong sign", "loss_pi = -agent.critic(obs, agent.actor(obs)).mean()",
         "loss_pi = agent.critic(obs, agent.actor(obs)).mean()"),
        ("policy loss summed, not averaged", "loss_pi = -agent.critic(obs, agent.actor(obs)).mean()",
         "loss_pi = -agent.critic(obs, agent.actor(obs)).sum()")],
    "pendulum_agent": [  # graded from the actor file beside the notebook, which these lack
        ("trains no step", "steps=steps, seed=seed", "steps=0, seed=seed"),
        ("saves nothing", "        ddpg.save_network(agent.actor, path)\n", "        pass\n")],
    "prediction_actor": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "0.5 and 1.")],
    "ou_step": [
        ("dt for sqrt(dt)", "sigma * np.sqrt(dt) *", "sigma * dt *"),
        ("drift away from mu", "theta * (mu - x)", "theta * (x - mu)")],
    "tet_signed_volumes": [
        ("unsigned volumes", "np.linalg.det(edges) / 6.0", "np.abs(np.linalg.det(edges)) / 6.0"),
        ("forgets the 1/6", "np.linalg.det(edges) / 6.0", "np.linalg.det(edges)")],
    "mesh_edges": [
        ("edges not deduplicated", "np.unique(np.sort(e, axis=1), axis=0)", "np.sort(e, axis=1)"),
        ("misses an edge of each tetrahedron", ", (2, 3)]", "]")],
    "surface_triangles": [
        ("interior faces", "keys[counts == 1]", "keys[counts == 2]"),
        ("every face", "keys[counts == 1]", "keys")],
    "lame_parameters": [
        ("swapped results", "return mu, lam", "return lam, mu"),
        ("shear modulus without the 2", "(2.0 * (1.0 + poisson_ratio))", "(1.0 + poisson_ratio)")],
    "prediction_substep": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "Both blow up, the 3 ms first.")],
    "split_observation": [
        ("desired read from the current nodes", '"desired": obs[6 + m3:6 + 2 * m3]', '"desired": obs[6:6 + m3]'),
        ("velocity read from the position", '"tip_velocity": obs[3:6]', '"tip_velocity": obs[0:3]')],
    "tip_target": [
        ("no workspace clipping", "return np.clip(target, low, high)", "return target"),
        ("forgets the action duration", "        * params.action_duration", "        * 1.0")],
    "mean_node_distance": [
        ("squared distances", "np.linalg.norm(diff, axis=-1)", "np.sum(diff ** 2, axis=-1)"),
        ("norm of all nodes at once", "np.mean(np.linalg.norm(diff, axis=-1))", "np.linalg.norm(diff) / len(diff)")],
    "step_outcome": [
        ("<= for <", "bool(distance < threshold)", "bool(distance <= threshold)"),
        ("> for >=", "steps >= max_episode_steps", "steps > max_episode_steps"),
        ("the garbage distance after a blow-up", "-last_distance, False, True, False",
         "-distance, False, True, False"),
        ("a blow-up not truncated", "-last_distance, False, True, False",
         "-last_distance, False, False, False")],
    "prediction_nothing": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "The same reward every time.")],
    "level_moves": [
        ("ignores the direction", "direction * sy", "sy"),
        ("floor for ceil", "math.ceil(ry / 2)", "ry // 2")],
    "sweep_offsets_inside": [
        ("offsets from the start corner, not the initial tip",
         "np.cumsum(np.concatenate([start, *levels]), axis=0)[len(start):]",
         "np.cumsum(np.concatenate(levels), axis=0)"),
        ("every level in the same direction", "(-1) ** level", "1"),
        ("borders outside", "(offsets >= np.asarray(region.low)) & (offsets <= np.asarray(region.high))",
         "(offsets > np.asarray(region.low)) & (offsets < np.asarray(region.high))"),
        ("any for all", "np.all(", "np.any(")],
    "prediction_inside": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "About forty per cent.")],
    "reduce_gradients": [
        ("mean and sum swapped", 'if op == "mean":', 'if op == "sum":'),
        ("mean for sum", "np.sum([np.asarray(grads[i]) for grads in per_rank], axis=0)",
         "np.mean([np.asarray(grads[i]) for grads in per_rank], axis=0)"),
        ("no ValueError (secondary requirement only)",
         '    if op not in ("sum", "mean"):\n        raise ValueError(f"op must be \'sum\' or '
         '\'mean\', got {op!r}")\n', "", 1.5)],
    "pack_gradients": [
        ("skips missing gradients", "for p in module.parameters() if p.requires_grad]",
         "for p in module.parameters() if p.requires_grad and p.grad is not None]"),
        ("includes frozen parameters", "for p in module.parameters() if p.requires_grad]",
         "for p in module.parameters()]")],
    "unpack_gradients": [
        ("includes frozen parameters", "        if not p.requires_grad:\n            continue\n", ""),
        ("never advances the offset", "offset += k", "offset += 0")],
    "sum_gradients_over_ranks": [
        ("no reduction", "comm.Allreduce(flat, total)", "total[:] = flat"),
        ("mean for sum", "comm.Allreduce(flat, total)",
         "comm.Allreduce(flat, total)\n    total /= comm.Get_size()"),
        ("reduces the parameters, not the gradients", _ALLREDUCE,
         _ALLREDUCE.replace("p.grad.reshape(-1)", "p.detach().reshape(-1)")
         .replace("p.grad.copy_(", "p.data.copy_("))],
    "prediction_transitions": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "32 times as many.")],
    "play_episode": [
        ("stores truncation as done", "buffer.add(obs, action, reward, next_obs, terminated)",
         "buffer.add(obs, action, reward, next_obs, terminated or truncated)"),
        ("never moves to the next observation", "        obs = next_obs\n", ""),
        ("> for >= (one transition too late)", "len(buffer) >= needed", "len(buffer) > needed"),
        ("warmup ignored", "needed = warmup or batch_size", "needed = batch_size"),
        ("one update per action, whatever updates_per_step",
         "for _ in range(updates_per_step):", "for _ in range(1):"),
        ("no update after the episode's last action",
         "        if update is not None and len(buffer) >= needed:",
         "        if update is not None and len(buffer) >= needed and not (terminated or "
         "truncated):")],
    "prediction_updates": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "Fourteen updates.")],
    "table_row": [
        ("sample standard deviation", "final.std()", "final.std(ddof=1)"),
        ("fraction for percent", "100.0 * done.mean()", "done.mean()")],
    "wilson_interval": [
        ("z for z squared in the centre", "(p + z * z / (2 * n))", "(p + z / (2 * n))"),
        ("normal approximation", "z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denominator",
         "z * math.sqrt(p * (1 - p) / n)")],
    "prediction_verdicts": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "In all six cells."),
        ("a count, long, with no reason that names what decides a verdict", WHOLE_ANSWER,
         WRONG_ANSWERS["prediction_verdicts"][0], AWAITS)],
    "adam_step": [
        ("no bias correction", "m_hat = m / (1 - beta1**t)", "m_hat = m"),
        ("eps inside the square root", "(np.sqrt(v_hat) + eps)", "np.sqrt(v_hat + eps)"),
        ("swapped betas", "m = beta1 * np.asarray(m) + (1 - beta1) * grad",
         "m = beta2 * np.asarray(m) + (1 - beta2) * grad")],
    "relabel": [
        ("reward of the wrong sign", '"rew": (-distance)', '"rew": (distance)'),
        ("goal taken from obs, not next_obs", "goals = achieved_next[goal_steps]",
         "goals = obs[:, -2 * width:-width].reshape(len(obs), n_nodes, 3)[goal_steps]"),
        ("sum over the nodes for mean", "np.mean(np.linalg.norm(diff, axis=-1), axis=-1)",
         "np.sum(np.linalg.norm(diff, axis=-1), axis=-1)"),
        ("squared distances", "np.linalg.norm(diff, axis=-1)", "np.sum(diff ** 2, axis=-1)")],
    "prediction_successes": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "About ten percent."),
        ("a share, long, with no reason why a copy succeeds", WHOLE_ANSWER,
         WRONG_ANSWERS["prediction_successes"][0], AWAITS)],
    "jacobian_from_probes": [
        ("J transposed", "    return transposed.T\n", "    return transposed\n"),
        ("each probe taken as one axis (finite differences of the diagonal only)",
         "transposed, *_ = np.linalg.lstsq(tip_moves, node_moves, rcond=None)",
         "transposed = node_moves / np.diag(tip_moves)[:, None]"),
        ("no check of the probes' span (secondary requirement only)",
         "    if np.linalg.matrix_rank(tip_moves) < 3:\n        raise ValueError(\"the probing "
         "moves must span the 3 axes of the tip\")\n", "", 1.5)],
    "broyden_update": [
        ("forgets J's prediction", "surprise = dp - jacobian @ du", "surprise = dp"),
        ("divides by |du|, not |du|^2", "np.outer(surprise, du) / norm2",
         "np.outer(surprise, du) / np.sqrt(norm2)"),
        ("ignores min_move", "if norm2 == 0.0 or np.sqrt(norm2) <= min_move:", "if norm2 == 0.0:"),
        ("updates the input in place", "    return jacobian + gain * np.outer(surprise, du) / norm2",
         "    jacobian += gain * np.outer(surprise, du) / norm2\n    return jacobian")],
    "damped_least_squares_step": [
        ("damping not squared", "damping ** 2 * np.eye", "damping * np.eye"),
        ("Jacobian transpose, not least squares", "return np.linalg.solve(normal, jacobian.T @ error)",
         "return jacobian.T @ error"),
        ("damping ignored", " + damping ** 2 * np.eye(jacobian.shape[1])", ""),
        ("no check of the damping (secondary requirement only)",
         "    if damping < 0:\n        raise ValueError(f\"damping must be >= 0, got {damping}\")\n",
         "", 1.5)],
    "own_agent_report": [
        ("hands in the shipped agent", "hand_in(agent, folder)", "hand_in(SHIPPED_AGENT, folder)"),
        ("hands in nothing", "return hand_in(agent, folder)", "return {}")],
    "saturation_report": [
        ("measured on the scaled action, not on tanh(u)", "squashed = torch.tanh(u).double()",
         "squashed = actor.squash(u).double()"),
        ("1 - |tanh| for the tanh's gradient", "(1.0 - squashed ** 2).mean()",
         "(1.0 - squashed.abs()).mean()"),
        ("mean of u, not of |u|", "u.double().abs().mean()", "u.double().mean()"),
        ("per-dimension share over the wrong axis", "beyond.mean(dim=0)", "beyond.mean(dim=1)")],
    "overestimation": [
        ("returns of the cut episode, without their tail",
         'rewards = np.asarray(episode["rew"], dtype=np.float64)',
         'rewards = np.asarray(episode["rew"], dtype=np.float64)[:compared]'),
        ("bias as G - Q", "np.mean(q - returns)", "np.mean(returns - q)"),
        ("no discount", "rewards[t] + gamma * running", "rewards[t] + running")],
    "smoothed_target_action": [
        ("noise not clipped", "eps = noise.clamp(-noise_clip, noise_clip)", "eps = noise"),
        ("action not clipped to the bounds",
         "return torch.clamp(action + action_scale * eps, low, high)",
         "return action + action_scale * eps"),
        ("noise not scaled to the action range", "action + action_scale * eps", "action + eps")],
    "td3_target": [
        ("max for min", "torch.min(next_q,", "torch.max(next_q,"),
        ("only the first critic", "for critic in critic_targets[1:]:",
         "for critic in critic_targets[1:1]:"),
        ("no done mask", "gamma * next_q * (1.0 - done)", "gamma * next_q"),
        ("no target policy smoothing", "        if noise is not None:\n",
         "        if False:\n")],
    "td3_update": [
        ("the actor steps at every update", "    if agent.updates % cfg.policy_delay != 0:\n",
         "    if False:\n"),
        ("the second critic never trained", "for critic, optimizer in zip(agent.critics, ",
         "for critic, optimizer in zip(agent.critics[:1], "),
        ("no pre-tanh penalty", " + cfg.preactivation_l2 * (u ** 2).mean()", ""),
        ("targets of the critics left behind",
         "        for target, net in pairs:", "        for target, net in pairs[:1]:")],
    "prediction_overestimation": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "DDPG overestimates more.")],
    "scale_params": [
        ("factor added, not multiplied", "getattr(params, name) * factor",
         "getattr(params, name) + factor"),
        ("a zero factor accepted", "factor > 0)", "factor >= 0)"),
        ("unknown names not refused", "if name not in PERTURBABLE:", "if name in ():")],
    "add_observation_noise": [
        ("noise on the goal P_d", "part = slice(6, 6 + 3 * n_nodes)",
         "part = slice(6 + 3 * n_nodes, 6 + 6 * n_nodes)"),
        ("noise on the whole observation", "part = slice(6, 6 + 3 * n_nodes)",
         "part = slice(None)"),
        ("std taken as a variance", "rng.normal(0.0, std,", "rng.normal(0.0, std ** 2,"),
        ("the input modified in place", "noisy = np.array(obs, copy=True)",
         "noisy = np.asarray(obs)"),
        ("zero noise still draws", "    if std == 0:\n        return noisy\n", "")],
    "draw_factors": [
        ("names in the order given", "for name in sorted(checked)", "for name in checked"),
        ("bounds swapped", "float(rng.uniform(*checked[name]))",
         "float(rng.uniform(checked[name][1], checked[name][0]))"),
        ("zero and negative bounds accepted", "if not (math.isfinite(bound) and bound > 0):",
         "if not math.isfinite(bound):")],
    "prediction_controller_vs_agent": [  # a choice among stated options: graded automatically
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("an outcome in words, no option's letter", WHOLE_ANSWER, "The agent wins."),
        ("no option chosen", WHOLE_ANSWER,
         "I will run the cell first and then read what the table says about both methods."),
        ("two options", WHOLE_ANSWER, "(a) or (b): one of the two will win, I cannot say which."),
        ("issue 51's vacuous sentence", WHOLE_ANSWER, VACUOUS)],
    "prediction_robustness": [  # a choice among stated options: graded automatically
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("a change in words, no option's letter", WHOLE_ANSWER, "The noise."),
        ("no option chosen", WHOLE_ANSWER,
         "I would rather wait for the benchmark to tell me what happens in each of the worlds."),
        ("every option", WHOLE_ANSWER, "(a), (b), (c), (d) or (e): any of them could happen."),
        ("a letter beyond the options", WHOLE_ANSWER, "(f) because the rod is long.")],
    "prediction_cells": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "About six cells."),
        ("a number, long, with no reason from the agents, goals or episodes", WHOLE_ANSWER,
         WRONG_ANSWERS["prediction_cells"][1], AWAITS)],
    "prediction_factor": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "The threshold."),
        ("a factor, long, with no mechanism", WHOLE_ANSWER,
         WRONG_ANSWERS["prediction_factor"][1], AWAITS)],
    "analysis_comparison": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("too short", WHOLE_ANSWER, "Ours are worse than the paper's in most cells, because "
         "they were trained on far fewer transitions."),
        ("long, with no source, numbers, intervals or cells", WHOLE_ANSWER,
         WRONG_ANSWERS["analysis_comparison"][0], AWAITS)],
    "analysis_next_step": [
        ("placeholder left", WHOLE_ANSWER, "YOUR ANSWER HERE"),
        ("empty", WHOLE_ANSWER, ""),
        ("long, an experiment unrelated to the evidence", WHOLE_ANSWER,
         WRONG_ANSWERS["analysis_next_step"][0], AWAITS)],
    "seed_interval": [
        ("population standard deviation", "values.std(axis=axis, ddof=1)", "values.std(axis=axis)"),
        ("normal quantile for t", "half = T_975[n - 1] *", "half = 1.96 *"),
        ("divides by n, not sqrt(n)", "/ np.sqrt(n)", "/ n"),
        ("spread over every number, not over the seeds", "values.std(axis=axis, ddof=1)",
         "values.std(ddof=1)"),
        ("no check of the number of seeds", "    if n - 1 not in T_975:\n        raise ValueError("
         "f\"a t-interval needs 2 to {max(T_975) + 1} runs, got {n}\")\n", "")],
    "table_verdict": [
        ("names read from the paper's side", 'return "above"\n    if paper_done_percent > high:\n        return "below"',
         'return "below"\n    if paper_done_percent > high:\n        return "above"'),
        ("the interval's ends left out of it", "if paper_done_percent < low:",
         "if paper_done_percent <= low:"),
        ("fractions against a percent", "(100 * x for x in wilson_interval(successes, episodes))",
         "wilson_interval(successes, episodes)")],
}
def notebook_exercises() -> dict[str, list[str]]:
    """Solution notebook stem -> its exercises, in order."""
    found: dict[str, list[str]] = {}
    for e in notebooks.exercises(SOLUTIONS):
        found.setdefault(e["notebook"], []).append(e["exercise"])
    return found


ROUNDS = range(max(len(mutants) for mutants in MUTANTS.values()))
"""Round k: every exercise's k-th mutant, in one grading of every lesson that has one."""


def mutate(source: str, old: str, new: str) -> str:
    assert old in source, f"the mutant's text is not in the solution: {old!r}"
    mutated = source.replace(old, new)
    assert mutated != source
    return mutated


def mutant_notebook(stem: str, folder: Path, k: int) -> dict[str, tuple]:
    """Write the solution notebook ``stem`` to ``folder`` with the k-th mutant of each of
    its exercises that has one; return the mutants applied, by exercise."""
    applied = {}
    folder.mkdir(parents=True, exist_ok=True)
    path = SOLUTIONS / f"{stem}.ipynb"
    nb = notebooks.read_notebook(path)
    for cell in nb["cells"]:
        info = notebooks.graded_info(cell)
        if info and len(MUTANTS.get(info["exercise"], ())) > k:
            mutant = MUTANTS[info["exercise"]][k]
            if mutant[1] == WHOLE_ANSWER:  # keep only the written answer's first line
                first = notebooks.cell_source(cell).split("\n", 1)[0]
                source = f"{first}\n{mutant[2]}" if mutant[2] else first
            else:
                source = mutate(notebooks.cell_source(cell), mutant[1], mutant[2])
            cell["source"] = source.splitlines(keepends=True)
            applied[info["exercise"]] = mutant
    notebooks.write_notebook(nb, folder / path.name)
    return applied


def test_every_exercise_has_at_least_two_mutants_scoring_zero():
    catalog = {e["exercise"] for e in notebooks.exercises(SOLUTIONS)}
    assert set(MUTANTS) == catalog
    for name, mutants in MUTANTS.items():
        zero = [m for m in mutants if (m[3] if len(m) > 3 else 0) == 0]
        assert len(zero) >= 2, name


@pytest.mark.parametrize("k", ROUNDS, ids=[f"round-{k}" for k in ROUNDS])
def test_mutants_score_zero(k, tmp_path, request):
    wanted = request.config.getoption("--mutants-of")
    applied = {}
    for stem, names in notebook_exercises().items():
        if any(len(MUTANTS.get(n, ())) > k for n in names) and (not wanted or wanted in stem):
            applied.update(mutant_notebook(stem, tmp_path / "student", k))
    if not applied:
        pytest.skip(f"no lesson matching {wanted!r} has a mutant in round {k}")
    out = tmp_path / "grades.json"
    env = dict(os.environ, DLO_COURSE_GRADING_TIMEOUT="60")
    proc = subprocess.run(grading_command(tmp_path / "student", json_out=out),
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=3600)
    assert out.is_file(), f"no grades written\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    grades = {e["exercise"]: e for e in json.loads(out.read_text())["exercises"]}

    def as_expected(entry, expected):
        if expected == AWAITS:
            return entry["earned"] == 0 and entry.get("pending") == entry["points"]
        return entry["earned"] == expected and not entry.get("pending")

    wrong = {name: (mutant[0], grades[name]["earned"], grades[name]["outcome"])
             for name, mutant in applied.items()
             if not as_expected(grades[name], mutant[3] if len(mutant) > 3 else 0)}
    assert not wrong, f"mutants that scored (or missed their partial credit or review): " \
                      f"{wrong}\n{proc.stdout[-4000:]}"
