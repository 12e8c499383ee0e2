"""The planned state now of a batched world: computed on first read, once per step.

:class:`PlannedNow` is the part of :class:`uasep_env.sim.world.World` that answers "where
should the formation be now": the planned centre, direction, and each UAV's planned position
and velocity at each environment's time (:func:`uasep_env.sim.formation.planned_state`).
They are computed lazily, so that a reset followed by a step (the vector envs) evaluates
them once, and a partial reset recomputes only its rows.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from uasep_env.sim.formation import PlannedTrajectory, planned_state

if TYPE_CHECKING:
    from uasep_env.scenarios.spec import ScenarioBatch

__all__ = ["PlannedNow"]


def _plan_property(index: int, doc: str) -> property:
    """A read-only attribute: item ``index`` of :meth:`PlannedNow._plan_arrays`."""
    return property(lambda self: self._plan_arrays()[index], doc=doc)


class PlannedNow:
    """Mixin of :class:`~uasep_env.sim.world.World`: the plan now, computed on first read.

    The world provides ``plan`` (:class:`PlannedTrajectory`), ``time`` and
    ``frozen_inputs()`` (its read-only views, ``"time"`` and ``"_plan_offsets"`` among
    them), and calls :meth:`_refresh_plan` after every step and full reset and
    :meth:`_reset_plan_rows` after a partial one.
    """

    plan: PlannedTrajectory
    time: np.ndarray

    if TYPE_CHECKING:

        def frozen_inputs(self) -> dict[str, np.ndarray]:  # noqa: D102 (the world's)
            ...

    def _refresh_plan(self) -> None:
        """Mark the plan stale; the next read of a ``plan_*`` attribute recomputes it.

        Lazy, so that a reset followed by a step (the vector envs) evaluates it once.
        """
        self._plan_now: tuple[np.ndarray, ...] | None = None
        self._plan_resets: list[tuple[np.ndarray, ScenarioBatch]] = []

    def _reset_plan_rows(self, rows: np.ndarray, batch: ScenarioBatch) -> None:
        """After a partial reset: the plan already computed is to get the ``rows`` at time 0.

        The same numbers, row by row, as recomputing every environment's plan, which the
        vector envs' autoresets would otherwise do for a few reset rows; applied at the next
        read (:meth:`_plan_arrays`), so not at all when a step comes first (the vector envs'
        next-step autoreset). Marks the plan stale instead when none was computed or the
        scenarios did not bring their plans.
        """
        if self._plan_now is None or batch.plan is None or batch.plan_offsets is None:
            self._refresh_plan()
            return
        self._plan_resets.append((rows, batch))

    def _plan_arrays(self) -> tuple[np.ndarray, ...]:
        """``(center, direction, pos, vel)`` of the plan now, computed once per step.

        New arrays each time, read-only: what a caller keeps stays as it was.
        """
        if self._plan_now is None:
            f = self.frozen_inputs()
            center, direction, pos, vel = planned_state(
                self.plan.frozen(), f["time"], f["_plan_offsets"]
            )
            for arr in (center, direction, pos, vel):
                arr.flags.writeable = False
            self._plan_now = (center, direction, pos, vel)
        elif self._plan_resets:
            arrays = [old.copy() for old in self._plan_now]  # what a caller kept stays
            for rows, batch in self._plan_resets:
                fresh = planned_state(batch.plan, np.zeros(len(rows)), batch.plan_offsets)
                for arr, new in zip(arrays, fresh, strict=True):
                    arr[rows] = new
            for arr in arrays:
                arr.flags.writeable = False
            self._plan_now = tuple(arrays)
        self._plan_resets.clear()
        return self._plan_now

    # The four arrays of _plan_arrays, in its order.
    plan_center = _plan_property(0, "``(E, 3)`` planned formation centre now (m), read-only.")
    plan_dir = _plan_property(1, "``(E, 3)`` unit direction of the planned path now, read-only.")
    plan_pos = _plan_property(2, "``(E, N, 3)`` each UAV's planned position now (m), read-only.")
    plan_vel = _plan_property(3, "``(E, N, 3)`` each UAV's planned velocity now (m/s), read-only.")

    def planned(self) -> tuple[np.ndarray, np.ndarray]:
        """Each UAV's planned position and velocity now, ``(E, N, 3)`` each (read-only)."""
        return self.plan_pos, self.plan_vel

    def plan_finished(self) -> np.ndarray:
        """``(E,)`` whether the planned trajectory has been flown to its end."""
        return self.plan.finished(self.time)
