"""Write the env cards, ``docs/envs/<Name>.md``, one per registered id, from the code.

Every fact on a card is read from the code when the card is written: the spaces and their
shapes from live environments (the PettingZoo and the Gymnasium view of the id), the
observation layout (:class:`uasep_env.interface.observation_layout.ObservationLayout`), the reward
terms and weights (:data:`uasep_env.interface.rewards.TERMS`, the id's ``reward`` config), the
cost terms and weights (:data:`uasep_env.interface.costs.TERMS`, the id's ``cost`` config), the
limits that end an episode (the id's ``uav`` config), how uniformly random actions end
episodes (played here), the arguments (:class:`uasep_env.config.EnvConfig`'s fields, with
the id's values) and the version history (:data:`uasep_env.registration.ENV_VERSIONS`).
``tests/test_env_cards.py`` checks that the committed cards are what this script writes,
so a card cannot go stale.

The GIFs (``docs/envs/<Name>.gif``, an episode of the paper's APF drawn by the package's
own renderer, :class:`uasep_env.viz.frames.Renderer`) need matplotlib (the ``viz``
extra) and are redrawn only with ``--gifs``; the test checks that each exists and stays
small, not its bytes (they depend on the matplotlib and Pillow versions).

    python tools/build_env_cards.py           # rewrite the cards (and docs/envs/index.md)
    python tools/build_env_cards.py --gifs    # also redraw the GIFs (a minute or two)
    python tools/build_env_cards.py --check   # exit 1 if a card is out of date
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import sys
from pathlib import Path

import numpy as np

import uasep_env
from uasep_env.config import EnvConfig, make_config
from uasep_env.interface.costs import TERMS as COST_TERMS
from uasep_env.interface.observation_layout import ObservationLayout
from uasep_env.interface.rewards import TERMS
from uasep_env.registration import ENV_IDS, ENV_VERSION, ENV_VERSIONS, FIRST_VERSION
from uasep_env.runtime.atomic import atomic_write
from uasep_env.scenarios import FAMILIES
from uasep_env.scenarios.registry import ScenarioFamily

ROOT = Path(__file__).resolve().parents[1]
CARDS = ROOT / "docs" / "envs"
COMMAND = "python tools/build_env_cards.py"

#: Seeds of the uniformly random episodes a card reports.
RANDOM_SEEDS = range(5)
#: The GIF's episode: its seed, one frame every this many steps, the frame size.
GIF_SEED = 0
GIF_EVERY = 20  # 1000 steps -> 51 frames
GIF_FIGSIZE = (8.96, 5.12)  # inches: the default frame's proportions
GIF_DPI = 62  # -> 555 x 317 pixels
GIF_COLOURS = 32  # palette size: keeps a GIF under 1 MB
GIF_FRAME_MS = 100


def card_name(env_id: str) -> str:
    """``uasep/PaperEncounter-v3`` -> ``PaperEncounter`` (the card's file name)."""
    return env_id.split("/", 1)[1].rsplit("-v", 1)[0]


def _code(text: object) -> str:
    return f"`{text}`"


def _table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def _kwargs(defaults: dict) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in defaults.items())


def _observation_rows(layout: ObservationLayout) -> list[list[str]]:
    """One row per block of the vector: its entries, what it is, its features."""
    rows = []
    start = 0
    blocks = [
        ("self", 1, "own state"),
        ("uav", layout.k_uavs, f"{layout.k_uavs} nearest UAV(s), {layout.width('uav')} each"),
        (
            "obstacle",
            layout.k_obstacles,
            f"{layout.k_obstacles} nearest obstacle(s), {layout.width('obstacle')} each",
        ),
    ]
    for block, k, what in blocks:
        width = k * layout.width(block)
        if width == 0:
            continue
        features = ", ".join(f"`{f.name}` ({f.size})" for f in layout.block(block))
        rows.append([f"{start}-{start + width - 1}", what, features])
        start += width
    if layout.base_action:
        rows.append([f"{start}-{start + 2}", "the APF's command", "`base_action` (3)"])
    return rows


def random_episode_ends(env_id: str, seeds: range = RANDOM_SEEDS) -> list[tuple[int, str]]:
    """``(steps, how)`` of episodes played with uniformly random actions, one per seed.

    ``how`` is ``"collision"``, ``"lost UAV"``, both, or ``"time limit"``. The actions are
    drawn from ``numpy.random.default_rng(seed)``, so the episodes are the same everywhere.
    """
    out = []
    for seed in seeds:
        env = uasep_env.parallel_env(**ENV_IDS[env_id])
        env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        steps, how = 0, "time limit"
        while env.agents:
            actions = {a: rng.uniform(-1.0, 1.0, 3).astype(np.float32) for a in env.agents}
            _, _, terminations, _, infos = env.step(actions)
            steps += 1
            if any(terminations.values()):
                flags = [
                    name
                    for key, name in (("collision", "collision"), ("lost", "lost UAV"))
                    if any(infos[a][key] for a in infos)
                ]
                how = " and ".join(flags)
        env.close()
        out.append((steps, how))
    return out


def _summary(family: ScenarioFamily) -> str:
    """The family's one-line summary; a mix's names its families (its own says "below")."""
    if family.mix is None:
        return family.summary
    names = ", ".join(f"`{name}`" for name in family.mix.weights)
    return f"One of the scenario families {names}, drawn per episode."


def _random_summary(env_id: str) -> str:
    by_how: dict[str, list[str]] = {}
    for steps, how in random_episode_ends(env_id):
        by_how.setdefault(how, []).append(str(steps))
    ends = "; ".join(
        f"{len(s)} ended by {'the ' if how == 'time limit' else 'a '}{how} "
        f"(at step{'s' if len(s) > 1 else ''} {', '.join(s)})"
        for how, s in by_how.items()
    )
    return (
        f"Uniformly random actions, {len(RANDOM_SEEDS)} episodes (seeds "
        f"{RANDOM_SEEDS.start}-{RANDOM_SEEDS.stop - 1}, actions from "
        f"`numpy.random.default_rng(seed)`): {ends}."
    )


def render_card(env_id: str) -> str:
    """The Markdown card of one registered id."""
    import gymnasium

    defaults = ENV_IDS[env_id]
    name = card_name(env_id)
    cfg = make_config(defaults)
    family = FAMILIES[cfg.scenario]
    penv = uasep_env.parallel_env(**defaults)
    genv = gymnasium.make(env_id)
    layout = penv.core.layout
    agent = penv.possible_agents[0]
    obs_space, act_space = penv.observation_space(agent), penv.action_space(agent)
    max_steps = genv.spec.max_episode_steps
    u = cfg.uav
    lines = [
        "<!-- Written by tools/build_env_cards.py from the code; do not edit by hand.",
        f"     Regenerate: {COMMAND} (add --gifs to redraw the GIF). -->",
        "",
        f"# `{env_id}`",
        "",
        f"![An episode of {env_id} under the paper's APF]({name}.gif)",
        "",
        f"*The paper's APF ({{class}}`uasep_env.policies.APF`), seed {GIF_SEED}, one frame "
        f"every {GIF_EVERY} steps ({GIF_EVERY * cfg.step_duration:g} s), drawn by "
        "{class}`uasep_env.viz.frames.Renderer`: the 3D view and the top view, UAV trails, "
        "planned tracks (dotted), obstacles (red crosses) and their predicted reachable "
        "ellipsoids.*",
        "",
        f"{_summary(family)} {family.parameters} (scenario family `{family.name}`, "
        "[Scenarios](../environment.md#scenarios)).",
        "",
        "| | |",
        "|---|---|",
        f'| Gymnasium | `gymnasium.make("{env_id}")`, '
        f'`gymnasium.make_vec("{env_id}", num_envs=64)` |',
        f"| PettingZoo | `uasep_env.parallel_env({_kwargs(defaults)})` |",
        f"| Agents | {cfg.n_uavs}: `{penv.possible_agents[0]}` ... `{penv.possible_agents[-1]}` |",
        f"| Obstacle slots | {cfg.n_obstacles} (model `{cfg.obstacle.model}`) |",
        f"| Action space, per agent | `{act_space}` |",
        f"| Observation space, per agent | `{obs_space}` |",
        f"| Global state (`state()`) | `{penv.state_space}` |",
        f"| Gymnasium action space | `{genv.action_space}` |",
        f"| Gymnasium observation space | `{genv.observation_space}` |",
        f"| Neighbours observed | {layout.k_uavs} nearest UAV(s) of {cfg.n_uavs - 1}, "
        f"{layout.k_obstacles} nearest obstacle(s) (`observation.k_uavs`, "
        "`observation.k_obstacles`) |",
        f"| Step | {cfg.step_duration:g} s |",
        f"| Episode | {cfg.episode_duration:g} s, {max_steps} steps (`spec.max_episode_steps`) |",
        f"| PettingZoo name | `{penv.metadata['name']}` |",
        "| Render modes | `human`, `rgb_array` (matplotlib: the `viz` extra) |",
        "",
        "## Actions",
        "",
        "Per agent, the commanded acceleration along north, east and down as a fraction of "
        f"`uav.max_accel` ({u.max_accel:g} m/s²); finite values outside `[-1, 1]` are clipped "
        'and counted in `infos[agent]["clipped_actions"]`. The Gymnasium view takes the '
        'agents\' actions concatenated, UAV-major. With `action={"mode": "residual_apf"}` '
        "the action corrects the APF's command ([Action modes](../environment.md#action-modes)).",
        "",
        "## Observations",
        "",
        f"Per agent, {layout.dim} normalised `float32` entries in `[-{cfg.observation.clip:g}, "
        f"{cfg.observation.clip:g}]`; the features are explained in "
        "[Observations](../environment.md#observations). The Gymnasium view concatenates the "
        "agents' vectors.",
        "",
        _table(["entries", "block", "features (size)"], _observation_rows(layout)),
        "",
        "## Rewards",
        "",
        "Per agent, the weighted sum of named terms ([Rewards](../environment.md#rewards)); "
        'each agent\'s unweighted terms are in `infos[agent]["reward_terms"]`, the '
        "Gymnasium view's reward is the agents' mean.",
        "",
        _table(
            ["term", "weight", "unweighted, per step"],
            [
                [
                    _code(t.name),
                    f"{getattr(cfg.reward, t.name):g}",
                    (
                        f"{t.low * max_steps:g} (x `max_steps`) on a collision, else 0"
                        if t.per_episode
                        else f"{t.low:+g}"
                        if t.low == t.high
                        else f"{t.low:g} to {t.high:g}"
                    ),
                ]
                for t in TERMS
            ],
        ),
        "",
        f"Shared fraction `reward.shared` = {cfg.reward.shared:g} (each agent's reward mixes "
        "in the team's mean by this much).",
        "",
        "## Costs",
        "",
        "The cost channel of constrained RL, beside the reward and in none of it "
        "([Costs](../environment.md#costs)): per agent, the weighted sum of indicator terms, "
        'each 1 in a step in which its safety flag holds; `infos[agent]["cost"]` and '
        '`infos[agent]["cost_terms"]` (the Gymnasium view: `info["cost"]`, the agents\' '
        "mean).",
        "",
        _table(
            ["term", "weight", "1 when"],
            [
                [_code(c.name), f"{getattr(cfg.cost, c.name):g}", f'`infos[agent]["{c.safety}"]`']
                for c in COST_TERMS
            ],
        ),
        "",
        "## Episode end",
        "",
        "* **Terminated**, for every agent at once: a collision (a UAV within "
        f"`uav.collision_distance` = {u.collision_distance:g} m of another UAV or an "
        'obstacle; `infos[agent]["collision"]`), or a **lost UAV**, farther than '
        f"`uav.lost_distance` = {u.lost_distance:g} m from its planned position "
        '(`infos[agent]["lost"]`).',
        f"* **Truncated** after `episode_duration` = {cfg.episode_duration:g} s "
        f"({max_steps} steps) or at the end of the plan.",
        "",
        _random_summary(env_id),
        "",
        "## Arguments",
        "",
        "Every field of {class}`~uasep_env.config.env.EnvConfig` is a keyword of "
        "`gymnasium.make`, `make_vec` and `parallel_env` (validated; nested groups take "
        "dicts). This id's top-level values:",
        "",
        _table(["argument", "value"], _argument_rows(cfg, defaults)),
        "",
        "## Version history",
        "",
        *_history(name),
        "",
    ]
    penv.close()
    genv.close()
    return "\n".join(lines)


def _argument_rows(cfg: EnvConfig, defaults: dict) -> list[list[str]]:
    rows = []
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        if dataclasses.is_dataclass(value):
            shown = f"{{class}}`~{type(value).__module__}.{type(value).__name__}`"
        else:
            shown = _code(repr(value))
        if f.name in defaults:
            shown += " (this id's default)"
        rows.append([_code(f.name), shown])
    return rows


def _history(name: str) -> list[str]:
    first = FIRST_VERSION.get(name, 0)
    return [
        f"* `-v{v}` (uasep-env {release}): {text}"
        for v, release, text in ENV_VERSIONS
        if first <= v <= ENV_VERSION
    ] + [
        "",
        "Env ids bump their `-vN` whenever episodes or rewards change; the package's version "
        "follows semantic versioning ([Citing and versions](../citing.md#versions)).",
    ]


def render_index() -> str:
    """``docs/envs/index.md``: every id, its table row and the cards' toctree."""
    rows = []
    for env_id, defaults in ENV_IDS.items():
        penv = uasep_env.parallel_env(**defaults)
        cfg = penv.config
        space = penv.observation_space(penv.possible_agents[0])
        rows.append(
            [
                f"[`{env_id}`]({card_name(env_id)}.md)",
                _summary(FAMILIES[cfg.scenario]),
                str(cfg.n_uavs),
                str(cfg.n_obstacles),
                _code(space.shape),
            ]
        )
        penv.close()
    header = ["id", "encounter", "UAVs", "obstacles", "observation per agent"]
    toctree = ["```{toctree}", ":hidden:", "", *(card_name(i) for i in ENV_IDS), "```"]
    return "\n".join(
        [
            "<!-- Written by tools/build_env_cards.py from the code; do not edit by hand.",
            f"     Regenerate: {COMMAND}. -->",
            "",
            "# Environments",
            "",
            "One card per registered id: its spaces and shapes, rewards, episode ends, "
            "arguments and version history, and an episode of the paper's APF. Every id is "
            "also a PettingZoo parallel environment (`uasep_env.parallel_env`, the same "
            "keywords).",
            "",
            _table(header, rows),
            "",
            *toctree,
            "",
        ]
    )


def cards() -> dict[Path, str]:
    """Every card's path and text, and the index's."""
    out = {CARDS / f"{card_name(i)}.md": render_card(i) for i in ENV_IDS}
    out[CARDS / "index.md"] = render_index()
    return out


def episode_frames(env_id: str) -> list[np.ndarray]:
    """The GIF's frames: the paper's APF flying the id's episode :data:`GIF_SEED`."""
    from uasep_env.policies import APF
    from uasep_env.viz.frames import Renderer

    env = uasep_env.parallel_env(**ENV_IDS[env_id])
    apf = APF(env.config)
    renderer = Renderer(mode="rgb_array", figsize=GIF_FIGSIZE, dpi=GIF_DPI)
    observations, _ = env.reset(seed=GIF_SEED)
    frames = [renderer.render(env.world)]
    step = 0
    while env.agents:
        observations, *_ = env.step({a: apf(observations[a]) for a in env.agents})
        step += 1
        if step % GIF_EVERY == 0 or not env.agents:
            frames.append(renderer.render(env.world))
    renderer.close()
    env.close()
    return frames


def gif_bytes(frames: list[np.ndarray]) -> bytes:
    """An endless GIF of ``frames`` (one shared adaptive palette: small and deterministic)."""
    from PIL import Image

    images = [Image.fromarray(f) for f in frames]
    # One palette for every frame, from a strip of all of them (no per-frame dithering).
    strip = Image.new("RGB", (images[0].width, images[0].height * len(images)))
    for i, im in enumerate(images):
        strip.paste(im, (0, i * im.height))
    palette = strip.quantize(colors=GIF_COLOURS, method=Image.Quantize.MEDIANCUT)
    quantized = [
        im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images
    ]  # fmt: skip
    buf = io.BytesIO()
    quantized[0].save(
        buf,
        format="GIF",
        save_all=True,
        append_images=quantized[1:],
        duration=GIF_FRAME_MS,
        loop=0,
        optimize=False,
    )
    return buf.getvalue()


def main(argv: list[str] | None = None) -> int:
    """Rewrite the cards (``--gifs``: and their GIFs), or check them (``--check``)."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--check", action="store_true", help="exit 1 if a card is out of date")
    p.add_argument("--gifs", action="store_true", help="redraw the GIFs too (the viz extra)")
    args = p.parse_args(argv)
    expected = cards()
    stale = sorted(
        str(path.relative_to(ROOT))
        for path, text in expected.items()
        if not path.exists() or path.read_text() != text
    )
    extra = sorted(
        str(path.relative_to(ROOT)) for path in CARDS.glob("*.md") if path not in expected
    )
    if args.check:
        if stale or extra:
            print(f"out of date: {', '.join(stale + extra)}: run {COMMAND}", file=sys.stderr)
            return 1
        return 0
    for path, text in expected.items():
        if str(path.relative_to(ROOT)) in stale:
            atomic_write(path, text)
            print(f"wrote {path.relative_to(ROOT)}")
    for name in extra:
        (ROOT / name).unlink()
        print(f"removed {name} (no such id)")
    if args.gifs:
        for env_id in ENV_IDS:
            path = CARDS / f"{card_name(env_id)}.gif"
            data = gif_bytes(episode_frames(env_id))
            atomic_write(path, data)
            print(f"wrote {path.relative_to(ROOT)} ({len(data) / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
