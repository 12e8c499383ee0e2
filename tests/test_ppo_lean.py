"""uasep_env.training.ppo_lean: SB3's PPO arithmetic without SB3's per-step layers."""

import gymnasium
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
torch = pytest.importorskip("torch")

from uasep_env.training import ppo_lean, ppo_shared  # noqa: E402


def test_gae_is_sb3s_rollout_buffer():
    """Advantages and returns as SB3's buffer computes them, episode ends included."""
    from stable_baselines3.common.buffers import RolloutBuffer

    rng = np.random.default_rng(0)
    steps, rows, gamma, lam = 7, 5, 0.97, 0.9
    rewards = rng.normal(size=(steps, rows)).astype(np.float32)
    values = rng.normal(size=(steps, rows)).astype(np.float32)
    starts = (rng.random((steps, rows)) < 0.3).astype(np.float32)
    last_value = rng.normal(size=rows).astype(np.float32)
    last_done = np.array([1, 0, 1, 0, 0], dtype=np.float32)
    space = gymnasium.spaces.Box(-1, 1, (2,), np.float32)
    buf = RolloutBuffer(steps, space, space, gamma=gamma, gae_lambda=lam, n_envs=rows)
    for t in range(steps):
        buf.add(np.zeros((rows, 2)), np.zeros((rows, 2)), rewards[t], starts[t],
                torch.from_numpy(values[t]), torch.zeros(rows))  # fmt: skip
    buf.compute_returns_and_advantage(torch.from_numpy(last_value), last_done)
    adv, ret = ppo_lean.gae(rewards, values, starts, last_value, last_done, gamma, lam)
    np.testing.assert_allclose(adv, buf.advantages, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(ret, buf.returns, rtol=1e-6, atol=1e-6)


class _Scripted(gymnasium.Env):
    """Random observations far from zero mean and unit scale; an episode ends every 3 steps."""

    observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (4,), np.float32)
    action_space = gymnasium.spaces.Box(-1, 1, (1,), np.float32)

    def __init__(self, k: int) -> None:
        self.rng, self.t, self.final = np.random.default_rng(k), 0, None

    def _obs(self) -> np.ndarray:
        return self.rng.normal(30.0, 40.0, 4).astype(np.float32)

    def reset(self, seed=None, options=None):
        self.t = 0
        return self._obs(), {}

    def step(self, action):
        self.t += 1
        obs = self._obs()
        done = self.t % 3 == 0
        if done:
            self.final = obs
        return obs, float(self.rng.normal(5.0, 3.0)), done, False, {}


@pytest.mark.parametrize("norm_reward", [False, True])
def test_the_normaliser_is_vecnormalize(norm_reward):
    """The same observations, rewards and terminal observations as SB3's VecNormalize."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    inner = [_Scripted(k) for k in range(3)]
    vn = VecNormalize(DummyVecEnv([lambda e=e: e for e in inner]), norm_reward=norm_reward,
                      gamma=0.9)  # fmt: skip
    norm = ppo_lean.Normaliser(4, 3, norm_obs=True, norm_reward=norm_reward, gamma=0.9)
    first = vn.reset()
    np.testing.assert_allclose(norm.observe(vn.get_original_obs(), update=True), first, 1e-6)
    for _ in range(8):
        obs, rew, dones, infos = vn.step(np.zeros((3, 1), np.float32))
        got = norm.observe(vn.get_original_obs(), update=True)
        np.testing.assert_allclose(got, obs, rtol=1e-6)
        np.testing.assert_allclose(norm.reward(vn.get_original_reward(), dones), rew, 1e-6)
        for k in np.flatnonzero(dones):  # normalised after the new observations' update
            want = infos[k]["terminal_observation"]
            np.testing.assert_allclose(norm.normalise(inner[k].final[None])[0], want, 1e-6)
    np.testing.assert_allclose(norm.obs_rms.mean, vn.obs_rms.mean)
    assert np.abs(got).max() <= ppo_lean.CLIP_OBS


def _tiny(**extra: object) -> object:
    flags = ["--n-envs", "2", "--n-steps", "16", "--batch-size", "32", "--n-epochs", "2",
             "--hidden", "8", "--total-timesteps", "288", "--episode-duration", "4"]  # fmt: skip
    for k, v in extra.items():
        flags += [f"--{k.replace('_', '-')}", str(v)]
    return ppo_shared.parse_args(["--out-dir", "unused", "--no-progress", *flags])


def _update_once(args: object, advantage_sign: float) -> tuple:
    """One update on one repeated observation whose +x actions have advantage ``sign``."""
    torch.manual_seed(0)
    nets = ppo_lean._ActorCritic(4, args)
    opt = torch.optim.Adam(nets.params, lr=1e-2, eps=1e-5)
    steps, rows = 4, 8
    x = torch.ones((steps, rows, 4))
    with torch.no_grad():
        mean = nets.mu(nets.pi(x))
        up = torch.zeros_like(mean)
        up[..., 0] = torch.tensor([0.3, -0.3]).repeat(rows // 2)
        act = mean + up
        logp = nets.log_prob(mean, act)
    adv = np.sign(up[..., 0].numpy()) * advantage_sign
    before = [p.detach().clone() for p in nets.params]
    ppo_lean._update(nets, opt, args, 0, x, act, logp, adv.astype(np.float32),
                     np.ones((steps, rows), np.float32))  # fmt: skip
    with torch.no_grad():
        moved = (nets.mu(nets.pi(x[0, :1])) - mean[0, :1])[0, 0].item()
    return nets, before, moved


def test_an_update_moves_the_actor_towards_actions_with_positive_advantage():
    args = _tiny()
    assert _update_once(args, +1.0)[2] > 0 > _update_once(args, -1.0)[2]


def test_the_critic_warmup_freezes_the_actor():
    # SB3's recipes count the rollout before its update: a warm-up of 2 is one critic-only update.
    assert _update_once(_tiny(critic_warmup=1), +1.0)[2] > 0
    nets, before, _ = _update_once(_tiny(critic_warmup=2), +1.0)
    n = len(nets.actor)
    after = nets.params
    assert all(torch.equal(a, b) for a, b in zip(before[:n], after[:n], strict=True))
    assert any(not torch.equal(a, b) for a, b in zip(before[n:], after[n:], strict=True))


def test_a_run_counts_its_steps_is_reproducible_and_exports_a_loadable_policy(tmp_path):
    from uasep_env.policies import load_policy

    args = _tiny()
    config = ppo_shared.make_env_config(args)
    runs = [ppo_lean.train(args, config) for _ in range(2)]
    (nets, norm, facts), (nets2, norm2, _) = runs
    assert facts["agent_steps"] == 288 == facts["updates"] * 16 * 2 * config.n_uavs
    assert facts["episodes"] > 0  # 4 s episodes: ends and resets inside the run
    assert all(facts[k] > 0 for k in ("env_s", "rollout_s", "learner_s"))
    assert facts["env_s"] + facts["rollout_s"] + facts["learner_s"] <= facts["wall_s"]
    # Same seed, same training: the weights and the statistics bit for bit.
    assert all(torch.equal(a, b) for a, b in zip(nets.params, nets2.params, strict=True))
    assert np.array_equal(norm.obs_rms.mean, norm2.obs_rms.mean)
    other = ppo_lean.train(_tiny(seed=7), config)[0]
    assert not all(torch.equal(a, b) for a, b in zip(nets.params, other.params, strict=True))
    path = ppo_lean.export_policy(nets, norm, config, args, tmp_path / "p.zip", {})
    policy = load_policy(path, config.replace(action={"mode": "direct"}))
    # The checkpoint's actor is the trained one: its mean on a normalised observation.
    raw = np.random.default_rng(0).normal(size=(1, norm.obs_rms.mean.shape[0]))
    with torch.no_grad():
        want = nets.mu(nets.pi(torch.from_numpy(norm.normalise(raw)))).numpy()
    np.testing.assert_allclose(policy.network(raw), want, rtol=1e-4, atol=1e-6)


def _pairs(nets: object, p: object) -> list:
    """Each lean parameter with its SB3 counterpart."""
    out = [(nets.log_std, p.log_std)]
    ext = p.mlp_extractor
    for mine, theirs in ((nets.pi, ext.policy_net), (nets.vf, ext.value_net),
                         (nets.mu, p.action_net), (nets.v, p.value_net)):  # fmt: skip
        out += list(zip(mine.parameters(), theirs.parameters(), strict=True))
    return out


def _sb3_weights_into(nets: object, p: object) -> None:
    """SB3's weights (its initial ones) into the lean networks."""
    with torch.no_grad():
        for a, b in _pairs(nets, p):
            a.copy_(b)


@pytest.mark.parametrize("target_kl", [0.0, 1e-9])
def test_an_update_is_sb3s_ppo_train(target_kl):
    """One update on the same rollout from the same weights: SB3's ``PPO.train``'s weights.

    One minibatch per epoch (its order then only reorders sums), so the two differ by float
    rounding only; with a tiny ``target_kl`` both stop at the second epoch's KL check.
    """
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import DummyVecEnv

    steps, rows, dim = 6, 4, 5
    args = _tiny(hidden="16,16", n_epochs=3, batch_size=steps * rows, ent_coef=0.01,
                 target_kl=target_kl, learning_rate=3e-3, log_std_init=-0.7)  # fmt: skip

    class Flat(gymnasium.Env):
        observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (dim,), np.float32)
        action_space = gymnasium.spaces.Box(-1, 1, (3,), np.float32)

    model = PPO("MlpPolicy", DummyVecEnv([Flat] * rows), n_steps=steps, batch_size=steps * rows,
                n_epochs=args.n_epochs, learning_rate=args.learning_rate, ent_coef=args.ent_coef,
                gamma=args.gamma, gae_lambda=args.gae_lambda, target_kl=target_kl or None,
                device="cpu", seed=0,
                policy_kwargs={"net_arch": {"pi": [16, 16], "vf": [16, 16]},
                               "activation_fn": torch.nn.Tanh, "log_std_init": -0.7})  # fmt: skip
    model.set_logger(configure(None, []))
    p = model.policy
    nets = ppo_lean._ActorCritic(dim, args)
    _sb3_weights_into(nets, p)
    before = [a.detach().clone() for a, _ in _pairs(nets, p)]
    rng = np.random.default_rng(3)
    torch.manual_seed(1)
    obs = torch.from_numpy(rng.normal(size=(steps, rows, dim)).astype(np.float32))
    with torch.no_grad():
        mean = nets.mu(nets.pi(obs))
        act = mean + nets.log_std.exp() * torch.randn_like(mean)
        logp = nets.log_prob(mean, act)
        values = nets.value(obs).numpy()
    rewards = rng.normal(size=(steps, rows)).astype(np.float32)
    starts = (rng.random((steps, rows)) < 0.2).astype(np.float32)
    last_value, last_done = rng.normal(size=rows).astype(np.float32), np.zeros(rows, np.float32)
    buf = model.rollout_buffer
    for t in range(steps):
        buf.add(obs[t].numpy(), act[t].numpy(), rewards[t], starts[t],
                torch.from_numpy(values[t]), logp[t])  # fmt: skip
    buf.compute_returns_and_advantage(torch.from_numpy(last_value), last_done)
    model.train()
    adv, ret = ppo_lean.gae(rewards, values, starts, last_value, last_done, args.gamma,
                            args.gae_lambda)  # fmt: skip
    opt = torch.optim.Adam(nets.params, lr=args.learning_rate, eps=1e-5)
    ppo_lean._update(nets, opt, args, 0, obs, act, logp, adv, ret)
    pairs = _pairs(nets, p)
    assert max(float((a - b).detach().abs().max()) for a, b in pairs) < 1e-5
    # Both moved (else the comparison says nothing), by as many steps.
    assert (
        min(float((a.detach() - b0).abs().max()) for (a, _), b0 in zip(pairs, before, strict=True))
        > 1e-4
    )


@pytest.mark.parametrize("mode", ["direct", "residual_apf"])
def test_a_rollout_is_sb3s_collect_rollouts(mode):
    """The recipes' SB3 stack and the lean loop, same weights and torch seed: the same rollout.

    Episodes of 4 s end inside it, so the time limit's bootstrap from the terminal
    observation (normalised after the statistics take the new batch) is compared too.
    """
    from stable_baselines3.common.logger import configure

    from uasep_env.envs.core import EnvCore

    args = _tiny(action_mode=mode, n_steps=48, total_timesteps=10**6)
    config = ppo_shared.make_env_config(args)
    venv, model = ppo_shared.build(args, config)
    model.set_logger(configure(None, []))
    _, callback = model._setup_learn(10**6)  # resets the envs: environment e gets seed + e
    core = EnvCore(config, n_envs=args.n_envs)
    nets = ppo_lean._ActorCritic(core.obs_dim, args)
    _sb3_weights_into(nets, model.policy)
    norm = ppo_lean.Normaliser(core.obs_dim, args.n_envs * config.n_uavs, norm_obs=True,
                               norm_reward=False, gamma=args.gamma)  # fmt: skip
    state = ppo_lean.State(nets=nets, learner=nets, opt=None, norm=norm)
    roll = ppo_lean._Rollout(core, state, args.n_steps)
    roll.reset(args.seed)
    torch.manual_seed(5)
    model.collect_rollouts(model.env, callback, model.rollout_buffer, args.n_steps)
    torch.manual_seed(5)
    roll.collect(args.gamma)
    buf = model.rollout_buffer
    assert state.episodes > 0 and buf.episode_starts[1:].any()  # episodes ended inside it
    np.testing.assert_array_equal(roll.starts, buf.episode_starts)
    np.testing.assert_array_equal(roll.obs_t.numpy(), buf.observations)
    np.testing.assert_array_equal(roll.act.numpy(), buf.actions)
    np.testing.assert_allclose(roll.values, buf.values, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(roll.logp.numpy(), buf.log_probs, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(roll.rewards, buf.rewards, rtol=1e-6, atol=1e-5)
    adv, ret = ppo_lean.gae(roll.rewards, roll.values, roll.starts, roll.last_value, roll.start,
                            args.gamma, args.gae_lambda)  # fmt: skip
    np.testing.assert_allclose(adv, buf.advantages, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(ret, buf.returns, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(norm.obs_rms.mean, venv.obs_rms.mean)


def _same(a: object, b: object) -> bool:
    return all(torch.equal(x, y.cpu()) for x, y in zip(a.params, b.params, strict=True))


def test_a_learner_on_its_own_copy_trains_what_the_shared_networks_train(monkeypatch):
    # --device cuda: the update trains a copy there and the rollout's networks take its
    # weights after each update. On the CPU that copy must change nothing, bit for bit.
    args = _tiny()
    config = ppo_shared.make_env_config(args)
    nets, norm, _ = ppo_lean.train(args, config)
    copies = []

    def copied(nets: object, device: object) -> object:
        copies.append(nets.copy_to(device))
        return copies[-1]

    monkeypatch.setattr(ppo_lean, "_learner", copied)
    nets2, norm2, _ = ppo_lean.train(args, config)
    (learner,) = copies
    assert learner is not nets2 and learner.params[0] is not nets2.params[0]
    assert _same(nets, nets2) and _same(nets2, learner)
    assert np.array_equal(norm.obs_rms.mean, norm2.obs_rms.mean)


def test_a_copy_of_the_networks_is_independent_until_it_loads_the_weights():
    nets = ppo_lean._ActorCritic(4, _tiny())
    twin = nets.copy_to(torch.device("cpu"))
    assert _same(nets, twin) and len(twin.params) == len(nets.params)
    with torch.no_grad():
        for p in twin.params:
            p.add_(1.0)
    assert not any(torch.equal(a, b) for a, b in zip(nets.params, twin.params, strict=True))
    assert isinstance(twin.log_std, torch.nn.Parameter) and twin.log_std is twin.actor[-1]
    nets.load_from(twin)
    assert _same(nets, twin)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
@pytest.mark.parametrize("central", [False, True])
def test_the_update_on_a_gpu_trains_what_the_cpu_trains(central):
    # The draws are the CPU's either way; only the GPU's float arithmetic differs, so the two
    # runs part by rounding alone over a short run. MAPPO's critic inputs go there too.
    tiny = _tiny_mappo if central else _tiny
    config = ppo_shared.make_env_config(tiny())
    cpu = ppo_lean.train(tiny(), config, central=central)
    gpu = ppo_lean.train(tiny(device="cuda"), config, central=central)
    for a, b in zip(cpu[0].params, gpu[0].params, strict=True):
        assert b.device.type == "cpu"  # the rollout's copy, which the export reads
        torch.testing.assert_close(a, b, rtol=1e-3, atol=1e-4)
    assert cpu[2]["agent_steps"] == gpu[2]["agent_steps"]


# MAPPO: the centralised critic (``central=True``).


def _tiny_mappo(**extra: object) -> object:
    from uasep_env.training import mappo

    flags = ["--n-envs", "2", "--n-steps", "16", "--batch-size", "32", "--n-epochs", "2",
             "--hidden", "8", "--total-timesteps", "288", "--episode-duration", "4",
             "--trainer", "lean"]  # fmt: skip
    for k, v in extra.items():  # True: a switch without a value
        flags += [f"--{k.replace('_', '-')}", *([] if v is True else [str(v)])]
    return mappo.parse_args(["--out-dir", "unused", "--no-progress", *flags])


def _central_rollout(n_steps: int = 48) -> tuple:
    """A MAPPO rollout whose core records every global state and every step's rewards."""
    from uasep_env.envs.core import EnvCore
    from uasep_env.interface.observation import state_dim

    args = _tiny_mappo(n_steps=n_steps)
    config = ppo_shared.make_env_config(args)
    core = EnvCore(config, n_envs=args.n_envs)
    states, steps = [], []
    state_of, step_of = core.state, core.step

    def state() -> np.ndarray:
        states.append(state_of().copy())
        return states[-1]

    def step(actions: np.ndarray) -> object:
        res = step_of(actions)
        steps.append((res.rewards.reshape(-1).copy(), res.terminated.copy(),
                      res.truncated.copy()))  # fmt: skip
        return res

    core.state, core.step = state, step
    torch.manual_seed(0)
    width = state_dim(config) + core.obs_dim
    nets = ppo_lean._ActorCritic(core.obs_dim, args, width)
    rows = args.n_envs * config.n_uavs
    norm = ppo_lean.Normaliser(core.obs_dim, rows, norm_obs=True, norm_reward=False, gamma=0.99)
    st = ppo_lean.State(nets=nets, learner=nets, opt=None, norm=norm,
                        critic_norm=ppo_lean.Normaliser(width, rows, norm_obs=True,
                                                        norm_reward=False, gamma=0.99),
                        value_scale=ppo_lean.ValueScale())  # fmt: skip
    # Value statistics away from (0, 1): the critic's outputs must be mapped back.
    st.value_scale.rms.mean, st.value_scale.rms.var = np.float64(5.0), np.float64(4.0)
    roll = ppo_lean._Rollout(core, st, n_steps)
    roll.reset(args.seed)
    roll.collect(args.gamma)
    return roll, st, states, steps, config.n_uavs, width


def test_mappos_critic_reads_each_agents_global_state_and_own_observation():
    roll, st, states, _, n, width = _central_rollout()
    assert len(states) == len(roll.rewards) + 1  # one a step, one for the last value
    ref = ppo_lean.Normaliser(width, roll.obs_t.shape[1], norm_obs=True, norm_reward=False,
                              gamma=0.99)  # fmt: skip
    for t in range(len(roll.rewards)):
        obs = roll.obs_t[t].numpy()
        # Row e * n + i is UAV i of environment e: its environment's state, its observation.
        x = np.stack([np.concatenate([states[t][r // n], obs[r]]) for r in range(len(obs))])
        want = ref.observe(x, update=True)
        np.testing.assert_array_equal(roll.crit_t[t].numpy(), want)
        with torch.no_grad():
            v = st.nets.value(roll.crit_t[t]).numpy()
        np.testing.assert_allclose(roll.values[t], v * 2.0 + 5.0, rtol=1e-6)
    # The state is the new episode's where one began: its progress is 0 there, else not.
    begins = roll.starts[1:, ::n] == 1
    assert begins.any()
    progress = np.stack(states[1:-1])[..., -1]
    assert np.all(progress[begins] == 0) and np.all(progress[~begins] > 0)
    # The last value's input leaves the statistics as they were (the next rollout counts it).
    np.testing.assert_array_equal(st.critic_norm.obs_rms.mean, ref.obs_rms.mean)


def test_mappos_time_limit_ends_the_episode_without_a_bootstrap():
    roll, _, _, steps, _, _ = _central_rollout()
    rewards = np.stack([s[0] for s in steps]).astype(np.float32)
    truncated = np.stack([s[2] & ~s[1] for s in steps])
    assert truncated.any()  # 4 s episodes: time limits inside the rollout
    np.testing.assert_array_equal(roll.rewards, rewards)


def test_the_value_scale_standardises_by_every_return_seen():
    rng = np.random.default_rng(1)
    scale = ppo_lean.ValueScale()
    batches = [rng.normal(50.0, 20.0, (16, 6)).astype(np.float32) for _ in range(3)]
    first = scale.scale(batches[0])
    assert abs(first.mean()) < 1e-4 and abs(first.std() - 1.0) < 1e-4
    for b in batches[1:]:
        z = scale.scale(b)
    seen = np.concatenate([b.reshape(-1) for b in batches]).astype(np.float64)
    np.testing.assert_allclose(scale.rms.mean, seen.mean(), rtol=1e-6)
    np.testing.assert_allclose(scale.rms.var, seen.var(), rtol=1e-5)
    np.testing.assert_allclose(scale.to_value(z), batches[-1], rtol=1e-5)


@pytest.mark.parametrize(("central", "value_norm"), [(False, True), (True, True), (True, False)])
def test_only_mappos_critic_learns_standardised_returns(monkeypatch, central, value_norm):
    seen = []
    real = ppo_lean._update

    def update(nets, opt, args, updates, obs, act, logp, adv, ret, crit=None):
        seen.append((ret.copy(), crit))
        return real(nets, opt, args, updates, obs, act, logp, adv, ret, crit)

    monkeypatch.setattr(ppo_lean, "_update", update)
    args = _tiny_mappo(**({} if value_norm else {"no_value_norm": True})) if central else _tiny()
    assert getattr(args, "value_norm", True) == value_norm
    ppo_lean.train(args, ppo_shared.make_env_config(args), central=central)
    ret, crit = seen[0]
    standardised = abs(ret.mean()) < 1e-3 and abs(ret.std() - 1.0) < 1e-3
    assert standardised == (central and value_norm)
    if central:  # the critic's own inputs, a row for each return
        assert crit.shape[:2] == ret.shape


def test_a_mappo_run_is_reproducible_and_exports_a_mappo_policy(tmp_path):
    from uasep_env.interface.observation import state_dim
    from uasep_env.policies import load_policy
    from uasep_env.policies.learned import read_checkpoint

    args = _tiny_mappo()
    config = ppo_shared.make_env_config(args)
    (nets, norm, facts), (nets2, _, _) = (
        ppo_lean.train(args, config, central=True) for _ in range(2)
    )
    assert facts["agent_steps"] == 288 and facts["episodes"] > 0
    assert all(torch.equal(a, b) for a, b in zip(nets.params, nets2.params, strict=True))
    obs_dim = norm.obs_rms.mean.shape[0]
    assert nets.vf[0].in_features == state_dim(config) + obs_dim
    assert nets.pi[0].in_features == obs_dim
    ppo = ppo_lean.train(_tiny(), config)[0]  # the same seed, PPO's critic: another run
    assert not torch.equal(nets.mu.weight, ppo.mu.weight)
    path = ppo_lean.export_policy(nets, norm, config, args, tmp_path / "p.zip", {})
    meta = read_checkpoint(path)[0]
    assert meta.algorithm == "MAPPO"
    assert meta.info["implementation"] == "uasep_env.training.ppo_lean (centralised critic)"
    policy = load_policy(path, config.replace(action={"mode": "direct"}))
    raw = np.random.default_rng(0).normal(size=(1, obs_dim))
    with torch.no_grad():
        want = nets.mu(nets.pi(torch.from_numpy(norm.normalise(raw)))).numpy()
    np.testing.assert_allclose(policy.network(raw), want, rtol=1e-4, atol=1e-6)


def test_mappos_grad_norm_clip_zero_is_no_clip():
    # skrl's meaning of 0; torch's clip to a norm of 0 would zero every gradient.
    assert _update_once(_tiny_mappo(grad_norm_clip=0), +1.0)[2] > 0
    assert _update_once(_tiny_mappo(grad_norm_clip=0), -1.0)[2] < 0
