"""What the agents see, do and are paid: the interface between the world and a policy.

* :mod:`~uasep_env.interface.observation_layout` -- the observation feature table and layouts.
* :mod:`~uasep_env.interface.observation` -- the observations computed from the world.
* :mod:`~uasep_env.interface.actions` -- the action modes (direct command, residual on the APF).
* :mod:`~uasep_env.interface.rewards` -- the reward-term table and the rewards.
* :mod:`~uasep_env.interface.costs` -- the cost-term table (the safe-RL cost channel).
* :mod:`~uasep_env.interface.outcome` -- one step's rewards, costs and safety flags together.

These read the world (:mod:`uasep_env.sim`) and never move it.
"""
