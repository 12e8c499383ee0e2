"""The simulated world and its physics: the one transition function and what it is built of.

* :mod:`~uasep_env.sim.world` -- :class:`World`, the batched core (arrays shaped
  ``(n_envs, n_agents, ...)``); its step moves everything.
* :mod:`~uasep_env.sim.physics_step` -- one step of the physics for a whole batch.
* :mod:`~uasep_env.sim.dynamics` -- eqs. 1-4: double integrator, speed limit, noise.
* :mod:`~uasep_env.sim.estimation` -- the batched Kalman filter.
* :mod:`~uasep_env.sim.formation` -- eqs. 5-7: the formation and its planned trajectory.
* :mod:`~uasep_env.sim.obstacles` -- the obstacles' 3D Dubins model.
* :mod:`~uasep_env.sim.noise` -- each environment's random stream.
* :mod:`~uasep_env.sim.geometry` -- UAV-UAV and UAV-obstacle distances.
* :mod:`~uasep_env.sim.replay` -- recorded tracks replayed as obstacles.

Nothing here imports the environments, the agents' interface or rendering.
"""
