"""The leaderboard's verdict in plain sentences, read from its numbers (never written by hand).

Each sentence is computed from a board (:func:`~uasep_env.benchmark.summary.leaderboard`):

* **safest** on a bank: the lowest collision rate at the default setting, then the lowest
  loss-of-separation (LoS) rate; the rows whose collision and LoS intervals both overlap the
  safest's are named as not distinguishable from it;
* **cheapest at equal safety**: the least deviation at equal safety (the bank's LoS budget,
  no collision, along each row's front);
* **beaten**: a row beats the APF on a bank when its collision and LoS intervals' upper
  ends are no higher than the APF's and its max deviation's interval lies wholly below the
  APF's (the defaults of both).

The sentences name the held-out bank first, then every other bank where the safest or the
cheapest changes, then where the paper's APF stands.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = ["beats", "cheapest", "safest", "sentences"]

#: The row every verdict compares with (the paper's APF).
REFERENCE = "apf"


def _rate(s: Mapping[str, Any]) -> str:
    return f"{s['rate']:.1%} [{s['ci_low']:.1%}, {s['ci_high']:.1%}]"


def _key(row: Mapping[str, Any]) -> tuple[float, float]:
    d = row["default"]
    return (d["collision"]["rate"], d["loss_of_separation"]["rate"])


def _overlap(a: Mapping[str, Any], b: Mapping[str, Any]) -> bool:
    return a["ci_low"] <= b["ci_high"] and b["ci_low"] <= a["ci_high"]


def safest(rows: Mapping[str, Any]) -> tuple[str, list[str]]:
    """The safest row's label and the rows not distinguishable from it (sorted by safety)."""
    order = sorted(rows, key=lambda k: _key(rows[k]))
    best = rows[order[0]]["default"]
    ties = [
        k
        for k in order[1:]
        if _overlap(rows[k]["default"]["collision"], best["collision"])
        and _overlap(rows[k]["default"]["loss_of_separation"], best["loss_of_separation"])
    ]
    return order[0], ties


def cheapest(rows: Mapping[str, Any]) -> str | None:
    """The row with the least deviation at equal safety (None: no row reaches the budget)."""
    reached = {k: r["equal_safety"]["deviation"] for k, r in rows.items()}
    reached = {k: v for k, v in reached.items() if v is not None}
    return min(reached, key=reached.__getitem__) if reached else None


def beats(row: Mapping[str, Any], reference: Mapping[str, Any]) -> bool:
    """Whether ``row`` beats ``reference`` at their defaults (see the module's rule)."""
    a, b = row["default"], reference["default"]
    dev_a, dev_b = a["max_deviation"], b["max_deviation"]
    if dev_a["ci_high"] is None or dev_b["ci_low"] is None:
        return False
    return (
        a["collision"]["ci_high"] <= b["collision"]["ci_high"]
        and a["loss_of_separation"]["ci_high"] <= b["loss_of_separation"]["ci_high"]
        and dev_a["ci_high"] < dev_b["ci_low"]
    )


def _safest_sentence(board: Mapping[str, Any], bank: str) -> str:
    rows = board["results"][bank]
    best, ties = safest(rows)
    d = rows[best]["default"]
    text = (
        f"On {board['banks'][bank]['title']} the safest at its default is **{best}** "
        f"(collisions {_rate(d['collision'])}, loss of separation "
        f"{_rate(d['loss_of_separation'])})"
    )
    if ties:
        text += f"; {', '.join(ties)} cannot be told apart from it (intervals overlap)"
    return text + "."


def _cheapest_sentence(board: Mapping[str, Any], bank: str) -> str:
    rows = board["results"][bank]
    budget = board["banks"][bank]["budget"]["loss_of_separation"]
    best = cheapest(rows)
    if best is None:
        return (
            f"On {board['banks'][bank]['title']} no row keeps loss of separation within "
            f"{budget:.1%} with no collision."
        )
    eq = rows[best]["equal_safety"]
    text = (
        f"At equal safety there (loss of separation within {budget:.1%}, no collision) the "
        f"cheapest is **{best}**, {eq['deviation']:.1f} m of max deviation"
    )
    ref = rows.get(REFERENCE)
    if ref is not None and best != REFERENCE:
        ref_dev = ref["equal_safety"]["deviation"]
        text += (
            f", the APF {ref_dev:.1f} m" if ref_dev is not None
            else ", where the APF's front does not reach the budget"
        )  # fmt: skip
    return text + "."


def _apf_sentence(board: Mapping[str, Any]) -> str:
    beaten: dict[str, list[str]] = {}
    for bank, rows in board["results"].items():
        if REFERENCE not in rows:
            continue
        winners = [k for k, r in rows.items() if k != REFERENCE and beats(r, rows[REFERENCE])]
        if winners:
            beaten[board["banks"][bank]["title"]] = winners
    if not beaten:
        return (
            "The paper's APF is not beaten at the defaults: on no bank is another row at least "
            "as safe (interval upper ends) with its deviation interval wholly below the APF's."
        )
    where = "; ".join(f"{title}: {', '.join(w)}" for title, w in beaten.items())
    return (
        "The paper's APF is beaten (at least as safe by the intervals' upper ends, its "
        f"deviation interval wholly below the APF's, both at their defaults) on {where}."
    )


def _current(board: Mapping[str, Any]) -> dict[str, Any]:
    """The board's results without the rows played in another env version (not comparable)."""
    env = board.get("versions", {}).get("env")
    return {
        bank: {k: r for k, r in rows.items() if r.get("env_version", env) == env}
        for bank, rows in board["results"].items()
    }


def sentences(board: Mapping[str, Any]) -> list[str]:
    """The verdict: the held-out bank first, then the banks where the order changes.

    Rows played in an earlier env version (checkpoints not yet retrained) are left out.
    """
    board = {**board, "results": _current(board)}
    banks = list(board["results"])
    if not banks:
        return []
    first = "held_out" if "held_out" in banks else banks[0]
    out = [_safest_sentence(board, first), _cheapest_sentence(board, first)]
    top = (safest(board["results"][first])[0], cheapest(board["results"][first]))
    for bank in banks:
        if bank == first:
            continue
        rows = board["results"][bank]
        if safest(rows)[0] != top[0]:
            out.append(_safest_sentence(board, bank))
        if cheapest(rows) != top[1]:
            out.append(_cheapest_sentence(board, bank))
    out.append(_apf_sentence(board))
    return out
