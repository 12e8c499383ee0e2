"""The env cards (``docs/envs/*.md``) are what ``tools/build_env_cards.py`` writes now.

The script reads every fact from the code and from live environments, so a change to the
spaces, the observation layout, the reward terms or weights, the episode ends, the
arguments or the env version makes these tests fail until the cards are rewritten.
"""

from __future__ import annotations

import runpy

import gymnasium
import pytest
from conftest import ROOT

import uasep_env
from uasep_env.registration import ENV_IDS, ENV_VERSION, ENV_VERSIONS

CARDS = runpy.run_path(str(ROOT / "tools" / "build_env_cards.py"))
FIX = "run: python tools/build_env_cards.py"


@pytest.fixture(scope="module")
def written() -> dict:
    return CARDS["cards"]()


def test_there_is_one_card_per_registered_id(written):
    names = {CARDS["card_name"](i) + ".md" for i in ENV_IDS} | {"index.md"}
    assert {p.name for p in written} == names
    on_disk = {p.name for p in (ROOT / "docs" / "envs").glob("*.md")}
    assert on_disk == names, f"cards on disk {sorted(on_disk)}, ids {sorted(names)}: {FIX}"


def test_the_committed_cards_are_up_to_date(written):
    for path, text in written.items():
        assert path.read_text() == text, f"{path.relative_to(ROOT)} is out of date: {FIX}"


def test_a_card_shows_the_live_spaces(written):
    for env_id in ENV_IDS:
        card = written[ROOT / "docs" / "envs" / f"{CARDS['card_name'](env_id)}.md"]
        genv = gymnasium.make(env_id)
        penv = uasep_env.parallel_env(**ENV_IDS[env_id])
        for space in (
            genv.observation_space,
            genv.action_space,
            penv.observation_space("uav_0"),
            penv.action_space("uav_0"),
            penv.state_space,
        ):
            assert f"`{space}`" in card, f"{env_id}: {space} not on its card"
        assert "lost UAV" in card and f"{penv.config.uav.lost_distance:g} m" in card
        assert f"![An episode of {env_id}" in card
        genv.close()
        penv.close()


def test_every_card_has_a_small_gif():
    for env_id in ENV_IDS:
        path = ROOT / "docs" / "envs" / f"{CARDS['card_name'](env_id)}.gif"
        assert path.exists(), f"{path.name} missing: python tools/build_env_cards.py --gifs"
        data = path.read_bytes()
        assert data[:6] == b"GIF89a", path.name
        assert len(data) < 1_000_000, f"{path.name}: {len(data)} bytes"
    image = pytest.importorskip("PIL.Image")
    with image.open(ROOT / "docs" / "envs" / "PaperEncounter.gif") as gif:
        assert 40 <= gif.n_frames <= 90 and gif.width <= 640


def test_every_env_version_has_a_history_row():
    # Bumping ENV_VERSION needs a row saying what changed (the cards' version history).
    versions = [v for v, _, _ in ENV_VERSIONS]
    assert versions == list(range(ENV_VERSION, -1, -1)), versions
    assert all(release and text for _, release, text in ENV_VERSIONS)


def test_check_names_a_stale_card(tmp_path, monkeypatch, capsys):
    globals_ = CARDS["main"].__globals__
    monkeypatch.setitem(globals_, "ROOT", tmp_path)
    monkeypatch.setitem(globals_, "CARDS", tmp_path / "docs" / "envs")
    monkeypatch.setitem(globals_, "random_episode_ends", lambda env_id: [(7, "lost UAV")])
    assert CARDS["main"]([]) == 0  # writes the cards into tmp_path
    assert CARDS["main"](["--check"]) == 0
    card = tmp_path / "docs" / "envs" / "Formation.md"
    card.write_text(card.read_text().replace("(58,)", "(57,)"))
    (tmp_path / "docs" / "envs" / "Old.md").write_text("an id that is gone")
    assert CARDS["main"](["--check"]) == 1
    err = capsys.readouterr().err
    assert "docs/envs/Formation.md" in err and "docs/envs/Old.md" in err
