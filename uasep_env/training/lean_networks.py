"""The lean PPO loop's learner: the actor-critic networks, one PPO update, the exported policy.

:mod:`~uasep_env.training.ppo_lean` runs the loop (rollouts, normalisation, GAE, the hooks);
this module holds what learns: SB3's ``MlpPolicy`` as the recipes configure it
(:class:`_ActorCritic`), SB3's ``PPO.train`` as one update (:func:`_update`), and the actor
written as the recipes' policy checkpoint (:func:`export_policy`). ``ppo_lean`` re-exports
them (its tests patch ``ppo_lean._update``: the loop calls the name it imported).
"""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.training.args import Args, hidden

__all__ = ["export_policy"]

_VF_COEF, _MAX_GRAD_NORM = 0.5, 0.5  # SB3 PPO's defaults, which the recipes keep


def _mlp(n_in: int, sizes: list[int], act: type, torch: Any) -> Any:
    layers: list = []
    for width in sizes:
        layers += [torch.nn.Linear(n_in, width), act()]
        n_in = width
    return torch.nn.Sequential(*layers)


def _init(module: Any, gain: float, torch: Any) -> None:
    """SB3's orthogonal initialisation (zero biases) of every linear layer of ``module``."""
    for m in module.modules():
        if isinstance(m, torch.nn.Linear):
            torch.nn.init.orthogonal_(m.weight, gain=gain)
            m.bias.data.fill_(0.0)


class _ActorCritic:
    """The recipes' networks: SB3's ``MlpPolicy`` with separate actor and critic MLPs.

    The critic reads ``critic_dim`` inputs (MAPPO's centralised critic), else the
    observation. Under ``--arch set`` (``args.arch``) the actor, and PPO's critic, are the
    permutation-invariant network over the neighbour slots of ``layout``
    (:mod:`~uasep_env.training.set_network_torch`); MAPPO's centralised critic stays an MLP
    over the global state.
    """

    def __init__(
        self, obs_dim: int, args: Args, critic_dim: int | None = None, layout: Any = None
    ) -> None:
        import torch

        sizes = hidden(args)
        act = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU}[args.activation]
        self.arch = getattr(args, "arch", "mlp")
        self.layout = layout
        self.centralised = critic_dim is not None
        if self.arch == "set":
            from uasep_env.training.set_network_torch import set_body

            self.pi, self.mu = set_body(layout, sizes, act, 3)
        else:
            self.pi, self.mu = _mlp(obs_dim, sizes, act, torch), torch.nn.Linear(sizes[-1], 3)
        if self.arch == "set" and not self.centralised:
            self.vf, self.v = set_body(layout, sizes, act, 1)
        else:
            self.vf = _mlp(critic_dim or obs_dim, sizes, act, torch)
            self.v = torch.nn.Linear(sizes[-1], 1)
        for body in (self.pi, self.vf):
            _init(body, math.sqrt(2.0), torch)
        _init(self.mu, 0.01, torch)
        _init(self.v, 1.0, torch)
        self.log_std = torch.nn.Parameter(torch.full((3,), float(args.log_std_init)))
        self._list_params()

    def _list_params(self) -> None:
        self.actor = [*self.pi.parameters(), *self.mu.parameters(), self.log_std]
        self.params = [*self.actor, *self.vf.parameters(), *self.v.parameters()]

    def copy_to(self, device: Any) -> _ActorCritic:
        """A copy of the networks on ``device`` (the learner's, beside the rollout's CPU copy)."""
        import torch

        twin = copy.deepcopy(self)
        for module in (twin.pi, twin.vf, twin.mu, twin.v):
            module.to(device)
        twin.log_std = torch.nn.Parameter(twin.log_std.detach().to(device))
        twin._list_params()
        return twin

    def load_from(self, other: _ActorCritic) -> None:
        """Take ``other``'s weights (same shapes, any device)."""
        import torch

        with torch.no_grad():
            for mine, theirs in zip(self.params, other.params, strict=True):
                mine.copy_(theirs)

    def value(self, obs: Any) -> Any:
        return self.v(self.vf(obs)).squeeze(-1)

    def log_prob(self, mean: Any, actions: Any) -> Any:
        """Sum over the action's components of the Gaussian's log-density."""
        z = (actions - mean) / self.log_std.exp()
        return (-0.5 * z * z - self.log_std - 0.5 * math.log(2.0 * math.pi)).sum(-1)

    def linears(self) -> list:
        """The actor's linear layers in order (what the policy checkpoint holds)."""
        import torch

        if self.arch == "set":
            return [*self.pi.linears(), self.mu]
        return [*(m for m in self.pi if isinstance(m, torch.nn.Linear)), self.mu]


def _update(
    nets: _ActorCritic,
    opt: Any,
    args: Args,
    updates: int,
    buf_obs: Any,
    buf_act: Any,
    buf_logp: Any,
    adv: np.ndarray,
    ret: np.ndarray,
    buf_crit: Any = None,
) -> None:
    """One PPO update (SB3's ``PPO.train`` as the recipes configure it), where ``nets`` are.

    The rollout's buffers are on the CPU; they go to ``nets``' device here. The minibatches'
    order is drawn on the CPU wherever the update runs, so a run draws the same numbers.
    ``buf_crit`` holds the critic's inputs (None or ``buf_obs`` itself: PPO's critic).
    """
    import torch

    device = nets.log_std.device
    # MAPPO's flags where the recipe has them, else SB3 PPO's defaults.
    vf_coef = getattr(args, "value_loss_scale", _VF_COEF)
    max_grad_norm = getattr(args, "grad_norm_clip", _MAX_GRAD_NORM)

    # The actor frozen, only the critic learns: as the SB3 recipes' callback, which counts
    # the rollout before its update, so the warm-up's last update trains the actor already.
    warm = updates + 1 < args.critic_warmup
    for p in nets.actor:
        p.requires_grad_(not warm)
    obs, act, old = (b.flatten(0, 1).to(device) for b in (buf_obs, buf_act, buf_logp))
    crit = obs if buf_crit is None or buf_crit is buf_obs else buf_crit.flatten(0, 1).to(device)
    adv_t = torch.from_numpy(adv.reshape(-1)).to(device)
    ret_t = torch.from_numpy(ret.reshape(-1)).to(device)
    size = len(obs)
    for _ in range(args.n_epochs):
        stop = False
        order = torch.randperm(size).to(device)
        for s in range(0, size, args.batch_size):
            idx = order[s : s + args.batch_size]
            x, a = obs[idx], act[idx]
            mean = nets.mu(nets.pi(x))
            logp = nets.log_prob(mean, a)
            value = nets.value(crit[idx])
            entropy = (nets.log_std + 0.5 + 0.5 * math.log(2.0 * math.pi)).sum().expand(len(idx))
            b = adv_t[idx]
            if len(idx) > 1:
                b = (b - b.mean()) / (b.std() + 1e-8)
            log_ratio = logp - old[idx]
            ratio = log_ratio.exp()
            lo, hi = 1.0 - args.clip_range, 1.0 + args.clip_range
            policy_loss = -torch.min(b * ratio, b * ratio.clamp(lo, hi)).mean()
            value_loss = torch.nn.functional.mse_loss(ret_t[idx], value)
            loss = policy_loss - args.ent_coef * entropy.mean() + vf_coef * value_loss
            with torch.no_grad():
                kl = ((ratio - 1.0) - log_ratio).mean().item()
            if args.target_kl and kl > 1.5 * args.target_kl:
                stop = True
                break
            opt.zero_grad()
            loss.backward()
            if max_grad_norm > 0:  # MAPPO's --grad-norm-clip 0: none, as skrl's
                torch.nn.utils.clip_grad_norm_(nets.params, max_grad_norm)
            opt.step()
        if stop:
            break


def export_policy(
    nets: _ActorCritic, norm: Any, config: Any, args: Args, path: Path, info: dict
) -> Path:
    """Write the actor and the normalisation as the recipes' policy checkpoint.

    MAPPO's (networks with a centralised critic) say so: algorithm ``"MAPPO"``.
    """
    from uasep_env.training.rundir import export_actor

    central = nets.centralised
    info = {**info, "implementation": "uasep_env.training.ppo_lean"
            + (" (centralised critic)" if central else "")}  # fmt: skip
    return export_actor(nets.linears(), norm, config, args, path,
                        "MAPPO" if central else "PPO", info, nets.arch)  # fmt: skip
