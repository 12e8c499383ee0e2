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

* **the learned policies against the best classical controller**: the best classical
  controller is, among the reference controllers that are the safest at their defaults or
  not told apart from the safest (among the reference controllers) on every bank of
  :data:`LEARNED_BANKS`, the one with the least mean max deviation on the held-out bank
  (none on every bank: the held-out bank's alone decides); a learned row (a checkpoint,
  shielded or not) *meets* it when on each of :data:`LEARNED_BANKS` its collision and LoS
  intervals' upper ends are no higher than the controller's, and on the held-out bank its
  max deviation's interval lies wholly below.

One sentence per group of banks (:data:`GROUPS`: synthetic, collision courses, formation
size, real traffic), each naming every bank's safest and cheapest, so a reader sees where the
order changes; then where the paper's APF stands, and how the learned policies fare against
the best classical controller.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from uasep_env.benchmark.runner import REFERENCE

__all__ = ["LEARNED_BANKS", "beats", "best_classical", "cheapest", "meets", "safest", "sentences"]

#: The banks on which a learned policy must be as safe as the best classical controller.
LEARNED_BANKS = ("held_out", "uavs_8", "uavs_32", "real_traffic")


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


def _bank_clause(board: Mapping[str, Any], bank: str) -> str:
    """One bank's safest row (with its ties) and its cheapest at equal safety."""
    rows = board["results"][bank]
    title = board["banks"][bank]["title"]
    best, ties = safest(rows)
    d = rows[best]["default"]
    text = (
        f"on {title} the safest at its default is **{best}** (collisions "
        f"{_rate(d['collision'])}, loss of separation {_rate(d['loss_of_separation'])}"
    )
    text += f"; {', '.join(ties)} not told apart from it)" if ties else ")"
    budget = board["banks"][bank]["budget"]["loss_of_separation"]
    fronts = board.get("settings", {}).get("front_banks")
    swept = fronts is None or bank in fronts
    at = "along each front" if swept else "the defaults only, no front swept there"
    low = cheapest(rows)
    if low is None:
        return text + f", and no row keeps loss of separation within {budget:.1%} collision-free"
    eq = rows[low]["equal_safety"]["deviation"]
    text += (
        f", and the cheapest at equal safety ({at}; loss of separation within {budget:.1%}, no "
        f"collision) is **{low}**, {eq:.1f} m of max deviation"
    )
    ref = rows.get(REFERENCE)
    if ref is not None and low != REFERENCE:
        ref_dev = ref["equal_safety"]["deviation"]
        text += f" (the APF {ref_dev:.1f} m)" if ref_dev is not None else " (the APF: not reached)"
    return text


#: The verdict's groups of banks, in order (a bank in no group gets a group of its own).
GROUPS = (
    ("Synthetic encounters", ("held_out",)),
    ("Collision courses", ("collision_head_on", "collision_crossing")),
    ("Formation size", ("uavs_8", "uavs_32")),
    ("Real traffic", ("real_traffic", "real_traffic_slow")),
)


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


def _classical(board: Mapping[str, Any], label: str) -> bool:
    """Whether a row is a registered reference controller (not a checkpoint, not shielded)."""
    from uasep_env.policies import REGISTRY

    spec = board.get("policies", {}).get(label, {}).get("spec", label)
    entry = REGISTRY.get(spec)
    return entry is not None and entry.reference


def best_classical(board: Mapping[str, Any]) -> str | None:
    """The best classical controller (the module's rule), or None."""

    def safe_set(bank: str) -> set[str]:
        rows = {k: r for k, r in board["results"].get(bank, {}).items() if _classical(board, k)}
        if not rows:
            return set()
        best, ties = safest(rows)
        return {best, *ties}

    held = {k: r for k, r in board["results"].get("held_out", {}).items() if _classical(board, k)}
    if not held:
        return None
    banks = [b for b in LEARNED_BANKS if b in board["results"]]
    candidates = set.intersection(*(safe_set(b) for b in banks)) or safe_set("held_out")
    return min(sorted(candidates), key=lambda k: held[k]["default"]["max_deviation"]["mean"])


def meets(board: Mapping[str, Any], learned: str, classical: str) -> list[str]:
    """Why ``learned`` does not meet ``classical`` (the module's rule); [] when it does."""
    why = []
    for bank in LEARNED_BANKS:
        rows = board["results"].get(bank, {})
        if learned not in rows or classical not in rows:
            why.append(f"not played on {bank}")
            continue
        a, b = rows[learned]["default"], rows[classical]["default"]
        for col, name in (("collision", "collisions"), ("loss_of_separation", "LoS")):
            if a[col]["ci_high"] > b[col]["ci_high"]:
                why.append(f"{name} on {bank} {_rate(a[col])} against {_rate(b[col])}")
    rows = board["results"].get("held_out", {})
    if learned in rows and classical in rows:
        a = rows[learned]["default"]["max_deviation"]
        b = rows[classical]["default"]["max_deviation"]
        if a["ci_high"] is None or b["ci_low"] is None or not a["ci_high"] < b["ci_low"]:
            why.append(f"max deviation on held_out {_mean(a)} against {_mean(b)} m")
    return why


def _mean(s: Mapping[str, Any]) -> str:
    if s["mean"] is None:
        return "-"
    return f"{s['mean']:.1f} [{s['ci_low']:.1f}, {s['ci_high']:.1f}]"


def _learned_sentence(board: Mapping[str, Any]) -> str | None:
    best = best_classical(board)
    learned = [k for k in board["results"].get("held_out", {}) if not _classical(board, k)]
    if best is None or not learned:
        return None
    head = (
        f"Learned policies against the best classical controller, **{best}** (the least "
        "deviation on the held-out bank among the controllers as safe as the safest, by "
        "overlapping intervals, on the held-out bank, at 8 and 32 UAVs and on real traffic; a "
        "learned policy meets it when it is as safe there, by the intervals' upper ends, and "
        "closer to the plan on the held-out bank, the intervals apart)"
    )
    met = [k for k in learned if not meets(board, k, best)]
    if met:
        dev = board["results"]["held_out"]
        parts = [f"**{k}** meets it ({_mean(dev[k]['default']['max_deviation'])} m of max "
                 f"deviation against {_mean(dev[best]['default']['max_deviation'])} m)"
                 for k in met]  # fmt: skip
        return f"{head}: {'; '.join(parts)}."
    parts = [f"{k}: {meets(board, k, best)[0]}" for k in learned]
    return f"{head}: none meets it ({'; '.join(parts)})."


def _current(board: Mapping[str, Any]) -> dict[str, Any]:
    """The board's results without the rows played in another env version (not comparable)."""
    env = board.get("versions", {}).get("env")
    current = {
        bank: {k: r for k, r in rows.items() if r.get("env_version", env) == env}
        for bank, rows in board["results"].items()
    }
    return {bank: rows for bank, rows in current.items() if rows}  # a bank with none: no clause


def sentences(board: Mapping[str, Any]) -> list[str]:
    """The verdict: a sentence per group of banks, then where the paper's APF stands.

    Rows played in an earlier env version (checkpoints not yet retrained) are left out.
    """
    board = {**board, "results": _current(board)}
    banks = list(board["results"])
    if not banks:
        return []
    grouped = [(name, [b for b in members if b in banks]) for name, members in GROUPS]
    known = {b for _, members in GROUPS for b in members}
    grouped += [(board["banks"][b]["title"], [b]) for b in banks if b not in known]
    out = []
    for name, members in grouped:
        if members:
            clauses = "; ".join(_bank_clause(board, b) for b in members)
            out.append(f"{name}: {clauses}.")
    out.append(_apf_sentence(board))
    learned = _learned_sentence(board)
    if learned:
        out.append(learned)
    return out
