"""Grading: lesson 4, DDPG (reference: dlo_course.ddpg, dlo_course.noise.OUNoise)."""

import copy
import random

import numpy as np
import pytest
import torch

from dlo_course import ddpg
from dlo_course.config import DDPGConfig
from dlo_course.noise import OUNoise

pytestmark = pytest.mark.notebook("04_ddpg")


def q_and_target(seed, batch=32):
    gen = torch.Generator().manual_seed(seed)
    q = (torch.randn(batch, 1, generator=gen) * 3).requires_grad_(True)
    return q, torch.randn(batch, 1, generator=gen)


def probe_loss(fn, batch):
    """Value and gradient (w.r.t. q) of a loss of q and a target for three seeds."""
    out = []
    for seed in range(3):
        q, target = q_and_target(seed, batch)
        loss = fn(q, target.clone())
        loss = torch.as_tensor(loss)
        (grad,) = torch.autograd.grad(loss, q) if loss.requires_grad else (None,)
        out.append({"loss": loss.detach(), "grad": grad})
    return out


def check_loss(got, want):
    for mine, ref in zip(got, want, strict=True):
        assert mine["loss"].dim() == 0, "the loss must be a scalar tensor"
        torch.testing.assert_close(mine["loss"].double(), ref["loss"].double())
        assert mine["grad"] is not None, "the loss must be differentiable with respect to q"
        torch.testing.assert_close(mine["grad"], ref["grad"])


def probe_critic_loss(fn):
    return probe_loss(fn, 32)


def probe_critic_loss_shapes(fn):
    """The exception raised for (B, 1) against (B,) and (B,) against (B, 1), or None."""
    q, target = q_and_target(9)
    raised = []
    for args in [(q, target.reshape(-1)), (q.reshape(-1), target)]:
        try:
            fn(*args)
            raised.append(None)
        except Exception as err:  # noqa: BLE001
            raised.append(type(err).__name__)
    return raised


@pytest.mark.exercise("critic_loss", points=1.5, reference="dlo_course.ddpg.critic_loss")
def test_critic_loss(student):
    check_loss(student.run(probe_critic_loss), probe_critic_loss(ddpg.critic_loss))


@pytest.mark.exercise("critic_loss", points=0.5, reference="dlo_course.ddpg.critic_loss")
def test_critic_loss_refuses_mismatched_shapes(student):
    """The secondary requirement (the ValueError), worth points only with a right loss."""
    try:
        check_loss(student.run(probe_critic_loss), probe_critic_loss(ddpg.critic_loss))
    except AssertionError:
        pytest.fail("the loss itself is wrong: no points for the shape check", pytrace=False)
    raised = student.run(probe_critic_loss_shapes)
    assert raised == ["ValueError", "ValueError"], \
        f"shapes (B, 1) and (B,) must raise ValueError (raised: {raised}); broadcasting them " \
        f"would compare every Q with every target"


POLYAK_CASES = [(0.01, False), (0.3, True), (1.0, False)]  # (tau, target requires grad)


def pair(seed):
    torch.manual_seed(seed)
    source = ddpg.Critic(5, 2, hidden_sizes=(16, 8), final_init=0.3)
    target = ddpg.Critic(5, 2, hidden_sizes=(16, 8), final_init=0.3)  # different weights
    return source, target


def probe_polyak_update(fn):
    out = []
    for tau, target_requires_grad in POLYAK_CASES:
        source, target = pair(int(tau * 100))
        target.requires_grad_(target_requires_grad)
        source_before = copy.deepcopy(source.state_dict())
        tensors = list(target.parameters())
        result = fn(target, source, tau)
        out.append({
            "returns_nothing": result is None or result is target,
            "params": [p.detach().clone() for p in target.parameters()],
            "in_place": all(a is b for a, b in zip(tensors, target.parameters())),
            "source_kept": all(torch.equal(v, source_before[k])
                               for k, v in source.state_dict().items()),
            "source_grads_none": all(p.grad is None for p in source.parameters())})
    return out


@pytest.mark.exercise("polyak_update", points=2, reference="dlo_course.ddpg.polyak_update")
def test_polyak_update(student):
    got = student.run(probe_polyak_update)
    for (tau, _), mine in zip(POLYAK_CASES, got, strict=True):
        source, expected = pair(int(tau * 100))
        with torch.no_grad():
            ddpg.polyak_update(expected, source, tau)
        assert mine["returns_nothing"], "update the target in place (and return nothing)"
        ref = list(expected.parameters())
        assert len(mine["params"]) == len(ref)
        for p, r in zip(mine["params"], ref):
            torch.testing.assert_close(p, r.detach(), rtol=1e-6, atol=1e-7)
        assert mine["in_place"], "the target's parameter tensors must be updated in place, " \
                                 "not replaced"
        assert mine["source_kept"], "the source must not change"
        assert mine["source_grads_none"], "the update must not leave gradients on the source"


OU_CASES = [(0, 3, 0.15, 0.3, 0.0, 1.0), (1, 1, 0.5, 0.1, 0.2, 1.0), (2, 4, 0.15, 0.2, -0.1, 0.05)]


def probe_ou_step(fn):
    out = []
    for seed, size, theta, sigma, mu, dt in OU_CASES:
        rng = np.random.default_rng(seed)
        x = np.full(size, mu, dtype=np.float64)
        states = []
        for _ in range(50):
            x = np.asarray(fn(x, rng, theta=theta, sigma=sigma, mu=mu, dt=dt))
            states.append(x)
        out.append(states)
    return out


@pytest.mark.exercise("ou_step", points=2, reference="dlo_course.noise.OUNoise.sample")
def test_ou_step(student):
    got = student.run(probe_ou_step)
    for (seed, size, theta, sigma, mu, dt), states in zip(OU_CASES, got, strict=True):
        noise = OUNoise(size, theta=theta, sigma=sigma, mu=mu, dt=dt, seed=seed)
        for x in states:
            noise.sample()
            assert x.shape == (size,)
            np.testing.assert_allclose(x, noise.state, rtol=1e-9, atol=1e-12)


# ------------------------------------------------------------------- ddpg_update

NETS = ("actor", "critic", "actor_target", "critic_target")
UPDATES = 3  # consecutive updates: the optimisers' state must carry over too


def update_agent(seed):
    """A small agent of the paper's kind whose targets trail its networks (as after some
    training), so that using the networks instead of the targets shows."""
    torch.manual_seed(seed)
    agent = ddpg.DDPG(5, 2, -1.0, 1.0, DDPGConfig(hidden_sizes=(16, 16), tau=0.1,
                                                        gamma=0.9))
    with torch.no_grad():
        for net in (agent.actor_target, agent.critic_target):
            for p in net.parameters():
                p.add_(0.1 * torch.randn(p.shape))
    return agent


def update_batch(seed, k, size=12):
    """Batch k: float32 tensors, rew and done of shape (B, 1), a quarter of them terminal."""
    gen = torch.Generator().manual_seed(seed + 1 + k)
    return {"obs": torch.randn(size, 5, generator=gen),
            "act": torch.rand(size, 2, generator=gen) * 2 - 1,
            "rew": torch.randn(size, 1, generator=gen),
            "next_obs": torch.randn(size, 5, generator=gen),
            "done": (torch.arange(size) % 4 == 0).float().reshape(size, 1)}


def probe_ddpg_update(fn, seed=41):
    """After each of UPDATES calls fn(agent, batch): every network's parameters, the
    gradients left on the critic and the actor, and whether the critic is trainable again.
    The agent's weights and the batches come from ``seed``."""
    agent = update_agent(seed)
    steps = []
    for k in range(UPDATES):
        fn(agent, update_batch(seed, k))

        def grads(net):
            return [None if p.grad is None else p.grad.detach().clone()
                    for p in net.parameters()]

        steps.append({
            "nets": {name: [p.detach().clone() for p in getattr(agent, name).parameters()]
                     for name in NETS},
            "critic_grads": grads(agent.critic), "actor_grads": grads(agent.actor),
            "critic_trainable": all(p.requires_grad for p in agent.critic.parameters())})
    return steps


def library_update(agent, batch):
    agent.update(batch)


UPDATE_HINTS = {  # what a difference in each place usually means
    "critic": "the critic step (its label: r + gamma * Q'(s', mu'(s')) * (1 - d) from the "
              "target networks, without gradient; the critic steps before the actor)",
    "critic_grads": "the critic's gradients after the update are not those of its own loss: "
                    "freeze the critic (requires_grad_(False)) during the actor step",
    "actor": "the actor step (the policy loss -mean Q(s, mu(s)) on the critic just updated)",
    "actor_grads": "the actor's gradients: those of the policy loss -mean Q(s, mu(s)) (minus "
                   "sign, mean over the batch), after the critic step",
    "actor_target": "the soft update of the actor's target",
    "critic_target": "the soft update of the critic's target",
}


def assert_tensors_close(mine, ref, what):
    assert len(mine) == len(ref), f"{what}: {len(mine)} tensors, expected {len(ref)}"
    for a, b in zip(mine, ref):
        assert a is not None, f"{what}: a gradient is missing"
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-6, msg=lambda m: f"{what}: {m}")


@pytest.mark.exercise("ddpg_update", points=4,
                      reference=("dlo_course.ddpg.DDPG.update", "dlo_course.ddpg.DDPG.target_value",
                                 "dlo_course.ddpg.DDPG._step", "dlo_course.ddpg.bellman_target",
                                 "dlo_course.ddpg.critic_loss", "dlo_course.ddpg.policy_loss",
                                 "dlo_course.ddpg.polyak_update"))
def test_ddpg_update(student):
    seed = random.SystemRandom().randrange(2**31)  # fresh weights and batches at every grading
    got = student.run(probe_ddpg_update, seed)
    want = probe_ddpg_update(library_update, seed)
    assert len(got) == UPDATES
    for k, (mine, ref) in enumerate(zip(got, want, strict=True), start=1):
        for name in ("critic", "critic_grads", "actor", "actor_grads", "actor_target",
                     "critic_target"):
            where = f"after update {k}, {name.replace('_', ' ')}: {UPDATE_HINTS[name]}"
            if name.endswith("_grads"):
                assert_tensors_close(mine[name], ref[name], where)
            else:
                assert_tensors_close(mine["nets"][name], ref["nets"][name], where)
        assert mine["critic_trainable"], \
            f"after update {k} the critic is still frozen: unfreeze it after the actor step"


@pytest.mark.exercise("prediction_actor", points=1)
def test_prediction_actor(written_answer):
    written_answer.check()


# ------------------------------------------------------------------ the Pendulum agent

# One re-evaluation: 10 episodes of 200 steps of a small actor, about a second of CPU; its
# own limit, with room for a busy machine.
REEVALUATION_TIMEOUT = 120.0


def probe_pendulum(_, actor_bytes):
    """In a sandbox worker that runs none of the student's code: the handed-in actor file
    (loaded with weights_only=True) played again on the graded episodes."""
    from pathlib import Path

    from dlo_course.pendulum import evaluate_actor_file

    path = Path("handed_in_pendulum_actor.pt")  # in the worker's scratch folder
    path.write_bytes(actor_bytes)
    return evaluate_actor_file(path)


@pytest.mark.timeout(REEVALUATION_TIMEOUT + 120)
@pytest.mark.exercise("pendulum_agent", points=2)
def test_pendulum_agent(notebook_folder, data_probe):
    """The points come from what the handed-in actor does, measured here: its mean return on
    the graded episodes must beat the floor, which no untrained actor reaches."""
    from dlo_course.pendulum import ACTOR_FILE, MAX_ACTOR_BYTES, RETURN_FLOOR

    path = notebook_folder / ACTOR_FILE
    if not path.is_file():
        pytest.fail(f"pendulum_agent: no {ACTOR_FILE} beside the notebook: run section 6 "
                    f"with your lessons 2 and 3 beside it, and hand the file in with the "
                    f"notebook", pytrace=False)
    if path.stat().st_size > MAX_ACTOR_BYTES:
        pytest.fail(f"pendulum_agent: {ACTOR_FILE} is larger than {MAX_ACTOR_BYTES} bytes",
                    pytrace=False)
    result = data_probe(probe_pendulum, path.read_bytes(), timeout=REEVALUATION_TIMEOUT)
    assert result["passed"], (
        f"pendulum_agent: your actor's mean return on the graded episodes is "
        f"{result['mean_return']:.0f}, not above the floor {RETURN_FLOOR:.0f} (an untrained "
        f"actor gets about -1100): see 'If your actor does not learn' in section 6")
