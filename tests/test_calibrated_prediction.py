"""The calibrated prediction (``prediction.fit="calibrated"``): table, regions, env, builder.

The builder (``tools/build_prediction_calibration.py``) is checked on a subset: the
helicopter and fixed-wing cells are rebuilt and must equal the shipped table's (the full
rebuild, about 80 s, reproduces the file byte for byte: a script check, see the docs).
"""

from __future__ import annotations

import copy
import hashlib
import importlib.util
import json
import runpy
from pathlib import Path

import numpy as np
import pytest

from uasep_env import make_config, reachable, real_traffic
from uasep_env.interface.observation_layout import ObservationLayout
from uasep_env.reachable import calibrated
from uasep_env.reachable.calibrated import (
    DEFAULT_TABLE,
    CalibrationTableError,
    calibrated_region,
    load_table,
)
from uasep_env.scenarios.real_traffic import REAL_TRAFFIC_BANK
from uasep_env.sim.obstacles import AIRCRAFT_CLASSES, DUBINS_CLASS, UNKNOWN_CLASS
from uasep_env.sim.world import World

ROOT = Path(__file__).resolve().parents[1]


def _calibrated_bank(**extra: object) -> dict:
    conf = copy.deepcopy(REAL_TRAFFIC_BANK)
    conf["prediction"] = {"fit": "calibrated", **extra}
    return conf


def test_the_shipped_table_has_its_provenance() -> None:
    tab = load_table()
    meta = tab.meta
    assert meta["alpha"] == 0.05 and meta["delta"] == 0.05
    sha = hashlib.sha256(real_traffic.DEFAULT_PATH.read_bytes()).hexdigest()
    assert meta["dataset"]["sha256"] == sha  # built from the shipped dataset
    test_flights = {t.flight for t in real_traffic.load().select("test")}
    for cls, splits in meta["flights"].items():
        assert set(splits) == {"train", "validation"}  # never the test flights
        assert not test_flights & (set(splits["train"]) | set(splits["validation"])), cls
    cells = json.loads(DEFAULT_TABLE.read_text())["cells"]["swept"]
    for cls, per_h in cells.items():
        for h, cell in per_h.items():
            assert cell["n_calibration_windows"] > 0, (cls, h)
            if cell["calibrated"]:  # the order statistic of the PAC bound, within n
                assert cell["k_pac"] <= cell["n_calibration_windows"]


def test_unknown_and_uncalibrated_classes_get_the_most_conservative_region() -> None:
    vel = np.array([[0.0, 0.0, 0.0], [30.0, 5.0, 1.0], [80.0, -10.0, -3.0]])
    pos = np.zeros_like(vel)
    regions = {
        c: calibrated_region(np.full(3, c), pos, vel, 10.0)[1] for c in range(len(AIRCRAFT_CLASSES))
    }
    for code, axes in regions.items():
        assert np.all(regions[UNKNOWN_CLASS] >= axes - 1e-12), AIRCRAFT_CLASSES[code]
    # A code outside the table is unknown too; the helicopter cells are not calibrated
    # (one validation flight), so it flies with the unknown region.
    assert np.array_equal(calibrated_region(np.full(3, 99), pos, vel, 10.0)[1], regions[0])
    heli = AIRCRAFT_CLASSES.index("helicopter")
    assert np.array_equal(regions[heli], regions[UNKNOWN_CLASS])
    assert np.all(regions[DUBINS_CLASS] < regions[UNKNOWN_CLASS])


def test_the_region_is_centred_on_the_constant_velocity_path() -> None:
    pos = np.array([10.0, -5.0, -100.0])
    vel = np.array([0.0, 20.0, -1.0])  # east, climbing
    c_sw, axes, psi = calibrated_region(2, pos, vel, 10.0, "swept")
    c_te, _, _ = calibrated_region(2, pos, vel, 10.0, "terminal")
    np.testing.assert_allclose(c_sw, pos + 5.0 * vel)
    np.testing.assert_allclose(c_te, pos + 10.0 * vel)
    assert psi == pytest.approx(np.pi / 2)
    # A larger inflation than the table's only grows every semi-axis, by the excess.
    _, grown, _ = calibrated_region(2, pos, vel, 10.0, inflation=load_table().inflation + 7.0)
    np.testing.assert_allclose(grown - axes, 7.0)


def test_uncalibrated_horizons_and_fits_are_refused_by_name() -> None:
    with pytest.raises(ValueError, match=r"prediction\.horizon=7"):
        make_config(prediction={"fit": "calibrated", "horizon": 7.0})
    with pytest.raises(ValueError, match=r"prediction\.fit"):
        make_config(prediction={"fit": "conformal"})
    with pytest.raises(ValueError, match="horizons"):
        calibrated_region(1, np.zeros(3), np.ones(3), 12.0)
    make_config(prediction={"fit": "calibrated", "horizon": 20.0})


@pytest.mark.parametrize(
    ("content", "match"),
    [
        (None, "no such file"),
        (b"{not json", "not valid JSON"),
        (b"[" * 40 + b"]" * 40, "nests 40 levels"),
        (b'{"format": "uasep-prediction-calibration", "version": 99}', "version 99"),
        (b'{"format": "other", "version": 1}', "format 'other'"),
        (b"\xff\xfe", "not UTF-8"),
        (b" " * (calibrated.MAX_TABLE_BYTES + 1), "larger than the limit"),
    ],
)
def test_bad_tables_are_one_line_errors_naming_the_file(
    tmp_path: Path, content: bytes | None, match: str
) -> None:
    path = tmp_path / "table.json"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(CalibrationTableError, match=match) as info:
        load_table(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_a_malformed_cell_is_named(tmp_path: Path) -> None:
    data = json.loads(DEFAULT_TABLE.read_text())
    data["cells"]["swept"]["glider"]["10"]["lateral"] = [-1.0, 3.0]
    path = tmp_path / "t.json"
    path.write_text(json.dumps(data))
    with pytest.raises(CalibrationTableError, match=r"cells\.swept\.glider\.10\.lateral"):
        load_table(path)


def _table_with(tmp_path: Path, edit: str) -> Path:
    """The shipped table with one value replaced by ``edit`` (raw JSON text, e.g. 1e308)."""
    data = json.loads(DEFAULT_TABLE.read_text())
    data["cells"]["swept"]["glider"]["10"]["lateral"] = ["@EDIT@", 3.0]
    path = tmp_path / "t.json"
    path.write_text(json.dumps(data).replace('"@EDIT@"', edit))
    return path


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        ("1e308", r"lateral is 1e\+308, expected a number in \[0, 100000\]"),
        (str(calibrated.MAX_COEFFICIENT * 1.5), r"expected a number in \[0, 100000\]"),
        ("1" + "0" * 399, r"lateral is an integer of 400 digits, too large for a float"),
        ("-1" + "0" * 399, r"lateral is an integer of 400 digits, too large for a float"),
    ],
)
def test_coefficients_are_bounded_and_huge_integers_named(
    tmp_path: Path, edit: str, match: str
) -> None:
    """A coefficient over the bound (1e308 gave infinite semi-axes) or an integer too large
    for a float (OverflowError) is a one-line CalibrationTableError (a ValueError)."""
    path = _table_with(tmp_path, edit)
    with pytest.raises(CalibrationTableError, match=match) as info:
        load_table(path)
    assert isinstance(info.value, ValueError)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_the_coefficient_bound_admits_the_shipped_table(tmp_path: Path) -> None:
    bound = calibrated.MAX_COEFFICIENT
    assert load_table(_table_with(tmp_path, repr(bound))).meta["version"] == 1
    for coef in load_table(DEFAULT_TABLE).coef.values():
        assert np.isfinite(coef).all() and coef.max() <= bound


def test_a_huge_integer_horizon_is_one_line(tmp_path: Path) -> None:
    text = DEFAULT_TABLE.read_text()
    data = json.loads(text)
    path = tmp_path / "t.json"
    path.write_text(json.dumps({**data, "horizons": ["@H@"]}).replace('"@H@"', "9" * 400))
    with pytest.raises(CalibrationTableError, match="OverflowError") as info:
        load_table(path)
    assert "\n" not in str(info.value) and len(str(info.value)) < 400


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="no FIFOs here")
def test_special_files_are_refused_before_opening(tmp_path: Path) -> None:
    """A FIFO is refused, not opened (opening one for read blocks until a writer comes)."""
    import os
    import threading

    fifo = tmp_path / "table.json"
    os.mkfifo(fifo)
    caught: list[BaseException] = []

    def read() -> None:
        try:
            load_table(fifo)
        except BaseException as exc:
            caught.append(exc)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(10.0)
    if reader.is_alive():  # blocked in open(): a writer's open releases it, then fail
        with open(fifo, "wb"):
            pass
        reader.join(10.0)
        pytest.fail(f"load_table opened the FIFO {fifo} for read and blocked")
    assert len(caught) == 1 and isinstance(caught[0], CalibrationTableError)
    assert "is not a regular file" in str(caught[0]) and str(fifo) in str(caught[0])
    with pytest.raises(CalibrationTableError, match="is not a regular file"):
        load_table(tmp_path)  # a folder


def test_obstacles_carry_their_aircraft_class() -> None:
    world = World(make_config(_calibrated_bank(), episode_duration=1.0), n_envs=3)
    world.reset(seed=6_000_000)
    tracks = real_traffic.load().tracks
    for i in range(3):
        from uasep_env.scenarios import sample_scenario

        spec = sample_scenario(np.random.default_rng(6_000_000 + i), world.config)
        want = AIRCRAFT_CLASSES.index(tracks[int(spec.obstacle_track_index[0])].aircraft_class)
        assert world.obstacles.aircraft_class[i, 0] == want
    synthetic = World(make_config(scenario="random", episode_duration=1.0), n_envs=2)
    synthetic.reset(seed=0)
    assert (synthetic.obstacles.aircraft_class == DUBINS_CLASS).all()


def test_the_env_region_holds_the_replayed_path() -> None:
    """In the world: the region predicted at t holds the true path over (t, t + 10 s].

    On 4 real-traffic episodes (test flights, 200 s, seeded): the calibration's target is
    95 %, and it holds here in 97.8 % of the windows (the regions shrunk to 0.6 of their size:
    92 %; the default enclosing region holds about 55 %).
    """
    h = 10.0
    world = World(make_config(_calibrated_bank(horizon=h), episode_duration=200.0), n_envs=4)
    world.reset(seed=6_000_000)
    steps = 1000
    zero = np.zeros((4, world.n_uavs, 3))
    centres, axes, heads, pos = [], [], [], []
    for k in range(steps + 1):
        if k:
            world.step(zero)
        centres.append(world.pred_center.copy())
        axes.append(world.pred_axes.copy())
        heads.append(world.pred_heading.copy())
        pos.append(world.obstacles.pos.copy())
    centres, axes, heads, pos = map(np.array, (centres, axes, heads, pos))
    n_h = round(h / world.config.dt)
    starts = np.arange(50, steps + 1 - n_h)
    ok = np.ones((len(starts), 4, 1), dtype=bool)
    for j in range(1, n_h + 1):
        ok &= reachable.contains(pos[starts + j], centres[starts], axes[starts], heads[starts])
    assert ok.mean() >= 0.95, ok.mean(axis=0)


def test_frozen_environments_keep_their_calibrated_region() -> None:
    world = World(make_config(_calibrated_bank(), episode_duration=4.0), n_envs=2)
    world.reset(seed=6_000_000)
    zero = np.zeros((2, world.n_uavs, 3))
    world.step(zero)
    before = world.pred_axes.copy()
    world.step(zero, active=np.array([True, False]))
    assert np.array_equal(world.pred_axes[1], before[1])  # not moved: not stepped
    assert not np.array_equal(world.pred_axes[0], before[0])


def test_the_class_feature_is_optional_and_one_hot() -> None:
    from uasep_env.interface.observation import build_observations
    from uasep_env.interface.observation_layout import FEATURES

    size = next(f.size for f in FEATURES if f.key == "obstacle_class")
    assert size == len(AIRCRAFT_CLASSES)

    conf = make_config(_calibrated_bank(), episode_duration=1.0)
    default = ObservationLayout.from_config(conf)
    assert "obstacle_class" not in default.features
    with_class = make_config(
        _calibrated_bank(),
        episode_duration=1.0,
        # Far enough to observe the placed track from the start.
        observation={
            "optional_features": ["obstacle_class"],
            "position_scale": 1000.0,
            "sensing_range": 10000.0,
        },
    )
    layout = ObservationLayout.from_config(with_class)
    world = World(with_class, n_envs=2)
    world.reset(seed=6_000_000)
    obs = build_observations(world, layout)
    dec = layout.decode(obs[0, 0])
    assert dec["obstacle_mask"][0]
    onehot = dec["obstacle_class"][0]
    assert onehot.sum() == 1.0
    assert AIRCRAFT_CLASSES[int(np.argmax(onehot))] in ("glider", "helicopter")
    assert int(np.argmax(onehot)) == world.obstacles.aircraft_class[0, 0]


def test_the_builder_rebuilds_the_shipped_cells() -> None:
    """The helicopter and fixed-wing cells (about 10 s) equal the shipped table's."""
    tool = runpy.run_path(str(ROOT / "tools" / "build_prediction_calibration.py"))
    fresh = json.loads(tool["dumps"](tool["build"](("helicopter", "fixed_wing"))))
    shipped = json.loads(DEFAULT_TABLE.read_text())
    for mode in ("swept", "terminal"):
        for cls in ("helicopter", "fixed_wing"):
            assert fresh["cells"][mode][cls] == shipped["cells"][mode][cls], (mode, cls)
    for key in ("alpha", "delta", "config", "dataset", "horizons", "inflation_m"):
        assert fresh[key] == shipped[key], key
    for cls in ("helicopter", "fixed_wing"):
        assert fresh["flights"][cls] == shipped["flights"][cls]


def test_real_traffic_eval_plays_every_registered_controller(monkeypatch) -> None:
    """The controller list comes from the policy registry (a controller added there appears)."""
    import dataclasses
    import sys

    from uasep_env import policies

    monkeypatch.syspath_prepend(str(ROOT / "baselines"))
    rte = __import__("real_traffic_eval")
    names = rte.registry_controllers()
    assert set(policies.POLICIES) - set(names) == {"zero", "random"}
    assert set(policies.shipped_policies()) <= set(names)
    entry = dataclasses.replace(policies.REGISTRY["apf"], name="new-controller")
    monkeypatch.setitem(policies.REGISTRY, "new-controller", entry)
    assert "new-controller" in rte.registry_controllers()
    assert rte.with_fit({"scenario": "random"}, "calibrated")["prediction"] == {"fit": "calibrated"}
    # Set explicitly: the default fit moved in -v3.
    assert rte.with_fit({"scenario": "random"}, "enclosing")["prediction"] == {"fit": "enclosing"}
    with pytest.raises(SystemExit):
        rte.main(["--prediction", "conformal"])
    sys.modules.pop("real_traffic_eval", None)


def test_every_class_list_derives_from_the_aircraft_class_table() -> None:
    """One table: the codes, the one-hot's width (numpy and the kernel's count), the
    coefficient rows, the builder's classes and the dataset's classes."""
    from uasep_env.interface.observation_layout import FEATURES
    from uasep_env.real_traffic import build as rt_build
    from uasep_env.sim import obstacles

    table = obstacles.AIRCRAFT_TABLE
    assert tuple(c.name for c in table) == AIRCRAFT_CLASSES
    assert len(set(AIRCRAFT_CLASSES)) == len(table)
    assert table[UNKNOWN_CLASS].name == "unknown" and table[UNKNOWN_CLASS].source is None
    assert table[DUBINS_CLASS].source == "synthetic"
    assert {c.source for c in table} <= {None, "synthetic", "real_traffic"}
    width = next(f.size for f in FEATURES if f.key == "obstacle_class")
    assert width == len(table)
    conf = make_config(_calibrated_bank(), observation={"optional_features": ["obstacle_class"]})
    assert ObservationLayout.from_config(conf).columns.n_classes == len(table)
    for coef in load_table().coef.values():
        assert coef.shape[0] == len(table)
    tool = runpy.run_path(str(ROOT / "tools" / "build_prediction_calibration.py"))
    assert tool["CLASSES"] == tuple(c.name for c in table if c.source is not None)
    real = tuple(c.name for c in table if c.source == "real_traffic")
    assert tool["REAL_CLASSES"] == rt_build.CLASSES == real_traffic.CLASSES == real


def test_the_kernel_one_hot_is_as_wide_as_the_table_says() -> None:
    """The kernel reads the one-hot's width from the layout's columns, not a constant: a
    layout told of fewer classes writes fewer entries (and the rest stay untouched)."""
    if importlib.util.find_spec("numba") is None:
        pytest.skip("numba not installed")
    from uasep_env._kernels import observations as kernel

    assert not hasattr(kernel, "_N_CLASSES")
    assert "cols.n_classes" in __import__("inspect").getsource(kernel)


@pytest.mark.parametrize("out", [None, "shipped"])
def test_the_builder_never_writes_some_classes_over_the_shipped_table(
    out: str | None, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--classes`` of a subset is refused before any build unless ``--out`` names another
    file (a partial table over the shipped one dropped the other classes' cells)."""
    tool = runpy.run_path(str(ROOT / "tools" / "build_prediction_calibration.py"))

    def build(classes: tuple[str, ...]) -> dict:
        raise AssertionError(f"built {classes}: the subset was not refused")

    monkeypatch.setitem(tool["main"].__globals__, "build", build)  # never writes a table
    before = DEFAULT_TABLE.read_bytes(), DEFAULT_TABLE.stat().st_mtime_ns
    argv = ["--classes", "glider"] + ([] if out is None else ["--out", str(DEFAULT_TABLE)])
    with pytest.raises(SystemExit) as info:
        tool["main"](argv)  # refused before building
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "some classes only" in err and "--out" in err and str(DEFAULT_TABLE) in err
    assert (DEFAULT_TABLE.read_bytes(), DEFAULT_TABLE.stat().st_mtime_ns) == before


def test_the_builder_writes_a_subset_to_another_file(tmp_path: Path, monkeypatch) -> None:
    """With ``--out`` elsewhere the subset is built there (build stubbed: the shipped
    cells' rebuild is test_the_builder_rebuilds_the_shipped_cells)."""
    tool = runpy.run_path(str(ROOT / "tools" / "build_prediction_calibration.py"))
    seen = []
    main = tool["main"]
    monkeypatch.setitem(main.__globals__, "build", lambda classes: seen.append(classes) or {})
    target = tmp_path / "glider.json"
    assert main(["--classes", "glider", "--out", str(target)]) == 0
    assert seen == [("glider",)] and json.loads(target.read_text()) == {}
