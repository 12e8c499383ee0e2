"""Keyword arguments taken from a command's options, by a table instead of one line each.

A command hands many of its options (an argparse namespace, a recipe's
:class:`~uasep_env.training.args.Args`) on to a function under the same or another name:
``uasep-eval``'s to :func:`~uasep_env.evaluation.evaluate`, a PPO recipe's to SB3's
``PPO``, the constraint's to its :class:`~uasep_env.training.lagrangian.PIDLagrangian`.
:func:`pick` is that hand-over, written once; the callers keep the table.
"""

from __future__ import annotations

from typing import Any

__all__ = ["pick"]


def pick(options: Any, *names: str, **renamed: str) -> dict[str, Any]:
    """``{name: options.name}`` for ``names``, and ``{keyword: options.field}`` for ``renamed``.

    Args:
        options: An object with the options as attributes.
        *names: Options passed under their own name.
        **renamed: ``keyword="field"``: the option ``field`` passed as ``keyword``.

    Raises:
        AttributeError: ``options`` has no such field (a table out of step with it).
    """
    return {
        **{name: getattr(options, name) for name in names},
        **{keyword: getattr(options, field) for keyword, field in renamed.items()},
    }
