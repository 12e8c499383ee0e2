"""Compiled (numba) forms of the hot numerical kernels; imported only when numba is in use.

Each kernel is the scalar, per-point transcription of a numpy function elsewhere in the
package and returns the same numbers bit for bit (``tests/test_kernels.py`` checks it): the
same operations in the same order, no ``fastmath``. The numpy forms stay the reference and
the fallback when numba is missing: each is decorated with
:func:`uasep_env._numba.compiled_twin`, which names its kernel here and the constants the
kernel receives as keyword arguments. These modules import nothing else of the package.

* :func:`nearest_on_ellipsoids` -- :func:`uasep_env.reachable.distance._nearest` (the body
  frame solve with the heading rotation around it);
* :func:`pairwise_distances` -- the same solve for every point against every ellipsoid of
  its batch row (:func:`uasep_env.reachable.distance._pairwise`), without broadcast copies,
  and :func:`region_distances`, the same from precomputed cosines and sines with the
  inactive regions at ``inf`` (:func:`uasep_env.reachable.distance.region_distances`);
* :func:`separations` -- :func:`uasep_env.sim.geometry.nearest_separations`;
* :func:`assemble_observations` -- :func:`uasep_env.interface.observation._assemble`;
* :func:`reward_terms` -- :func:`uasep_env.interface.rewards._weighted_terms`, and with the step's
  episode-end tests, safety flags and costs, :func:`step_outcome` --
  :func:`uasep_env.interface.outcome.step_outcome`;
* :func:`plan_now` -- :func:`uasep_env.sim.formation.planned_state`;
* :func:`double_integrator` -- :func:`uasep_env.sim.dynamics.step_double_integrator`,
  :func:`obstacle_step` -- :func:`uasep_env.sim.obstacles.step_obstacles` and
  :func:`kalman_correct` -- :func:`uasep_env.sim.estimation.kalman_correct`, and the whole
  physics step they make with the measurements and separations, :func:`physics_step` --
  :func:`uasep_env.sim.physics_step.physics_step` (these write the world's arrays in place);
* :func:`fit_ellipse` -- :func:`uasep_env.reachable.fit._fit_certified` (the enclosing
  ellipse's centre search, axes and certificate), :func:`ellipse_start` --
  :func:`uasep_env.reachable.fit._ellipse_start` (its start from the shape table) and
  :func:`node_arguments` -- :func:`uasep_env.reachable.fit._node_arguments` (the
  arctangent's arguments of its nodes) and :func:`ellipse_nodes` --
  :func:`uasep_env.reachable.fit._ellipse_nodes` (its nodes, sorted, with their cosines and
  sines);
* :func:`dense` -- :func:`uasep_env.policies.checkpoint_policy.dense_sums` (a policy
  network's layer, in float64 before the rounding);
* :func:`refill_noise` -- :func:`uasep_env.sim.noise.refill_noise` (numpy's PCG64 draws of
  the environments' noise blocks, compiled);
* :func:`encounter_draws` -- :func:`uasep_env.scenarios.batched.encounter_draws` (a
  partial reset's episodes' draws from their generators, numpy's algorithms on PCG64's
  state) and :func:`scenario_geometry` --
  :func:`uasep_env.scenarios.batch_geometry.scenario_geometry` (a partial reset's episodes
  built from their draws: plans, starts, obstacles);
* :func:`apf_actions` -- :func:`uasep_env.policies.apf._apf_actions` (the paper's APF's
  decision from the observations).
"""

from __future__ import annotations

from uasep_env._kernels.apf import apf_actions
from uasep_env._kernels.draws import encounter_draws
from uasep_env._kernels.ellipse_fit import (
    ellipse_nodes,
    ellipse_start,
    fit_ellipse,
    node_arguments,
)
from uasep_env._kernels.ellipsoids import (
    nearest_on_ellipsoids,
    pairwise_distances,
    region_distances,
)
from uasep_env._kernels.network import dense
from uasep_env._kernels.noise import refill_noise
from uasep_env._kernels.observations import assemble_observations
from uasep_env._kernels.physics import (
    double_integrator,
    kalman_correct,
    obstacle_step,
    physics_step,
)
from uasep_env._kernels.plan import plan_now
from uasep_env._kernels.rewards import reward_terms, step_outcome
from uasep_env._kernels.scenario import scenario_geometry
from uasep_env._kernels.separations import separations

__all__ = [
    "apf_actions",
    "assemble_observations",
    "dense",
    "double_integrator",
    "ellipse_nodes",
    "ellipse_start",
    "encounter_draws",
    "fit_ellipse",
    "kalman_correct",
    "nearest_on_ellipsoids",
    "node_arguments",
    "obstacle_step",
    "pairwise_distances",
    "physics_step",
    "plan_now",
    "refill_noise",
    "region_distances",
    "reward_terms",
    "scenario_geometry",
    "separations",
    "step_outcome",
]
