"""station.diagnose.effect_registry: one object per candidate effect with all its parts, and the only list of names."""

from __future__ import annotations

import ast
import math
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from station.diagnose import candidates, likelihood, rerun
from station.diagnose import effect_registry as registry
from station.diagnose.effect_registry import EFFECTS, NAMES, REGISTRY, engineering, simulator_input, unit_factor
from station.diagnose.finding_compensation import compensation
from station.diagnose.residuals import fit_baseline
from station.fit.compensation import APPLIED, COMPENSATION
from station.kernel.plan import RigPlan
from station.physics.effects import Effects
from station.sim.session_sim import simulate_session

DIAGNOSE = Path(registry.__file__).parent
PLAN = RigPlan(rest_s=60.0, pose_hold_s=8.0, rate_steps=(("x", 100.0), ("y", -100.0), ("z", 200.0)),
               rate_hold_s=4.0)


@pytest.mark.parametrize("effect", EFFECTS, ids=lambda e: e.name)
def test_every_effect_has_all_its_parts(effect: registry.Effect) -> None:
    assert effect.kind in ("mean", "noise", "count")
    assert effect.sensors and set(effect.sensors) <= {"accel", "gyro"}
    assert effect.description
    # regressors: exactly the mean candidates have them
    assert (effect.build is not None) == (effect.kind == "mean")
    # engineering units for every sensor it applies to
    for sensor in effect.sensors:
        factor, unit = effect.units[sensor]
        assert math.isfinite(factor) and factor > 0 and unit
    # a simulator mapping, or an explicit reason why none
    assert (effect.simulate is None) == bool(effect.not_simulated)
    assert effect.kind == "mean" or effect.simulate is None
    # a compensation mapping onto the parameter set's effects, or an explicit reason why the output keeps it
    assert effect.compensation is None or effect.compensation in COMPENSATION
    if effect.compensation not in APPLIED:
        assert effect.not_compensated
    # identifiability: what the recording needs and the rig step that separates it
    assert effect.identifiability.needs and effect.identifiability.rig_step
    # what a rig-free recording cannot test: per sensor it applies to, with the reason
    assert set(effect.identifiability.rig_free) <= set(effect.sensors)
    assert all(effect.identifiability.rig_free.values())


def test_the_registry_is_the_only_list_of_names() -> None:
    assert len(set(NAMES)) == len(NAMES) == len(EFFECTS)
    # every effect of the simulator's physics is a candidate of the diagnosis
    assert {f.name for f in fields(Effects)} <= set(NAMES)
    # and every effect the parameter set knows is some candidate's compensation
    assert set(COMPENSATION) <= {e.compensation for e in EFFECTS} | set(NAMES)
    # the per-name views elsewhere are derived from it
    assert tuple(e.name for e in EFFECTS if e.build is not None) == registry.MEAN_CANDIDATES
    assert set(rerun.SIMULATED) | set(rerun.STOCHASTIC) <= set(NAMES)
    assert set(rerun.SIMULATED) == {e.name for e in EFFECTS if e.simulate is not None}
    assert set(likelihood.PROFILE_TC) == {e.name for e in EFFECTS if e.identifiability.profile_tc}
    assert set(likelihood.WANDER_LIKE) == {e.name for e in EFFECTS if e.identifiability.wander_like}
    assert likelihood.WANDER_LIKE == ("temperature_bias",)
    # the regressors' module holds no view of the registry (it is imported by it)
    assert not hasattr(candidates, "LIBRARY") and not hasattr(candidates, "RIG_STEPS")
    # no other module of the diagnosis holds a table (tuple, list, set, dict) naming two or more effects
    for path in sorted(DIAGNOSE.glob("*.py")):
        if path.name == "effect_registry.py":
            continue
        tree = ast.parse(path.read_text())
        exports = {id(n.value) for n in ast.walk(tree)  # __all__ lists functions, e.g. candidates' regressors
                   if isinstance(n, ast.Assign) and any(getattr(t, "id", "") == "__all__" for t in n.targets)}
        for node in ast.walk(tree):
            if id(node) in exports:
                continue
            items = node.keys if isinstance(node, ast.Dict) else getattr(node, "elts", None)
            if not isinstance(node, ast.Tuple | ast.List | ast.Set | ast.Dict) or items is None:
                continue
            named = {i.value for i in items if isinstance(i, ast.Constant) and i.value in REGISTRY}
            assert len(named) < 2, f"{path.name}:{node.lineno} lists effects {sorted(named)}: use the registry"


def test_engineering_units_from_the_registry() -> None:
    cov = np.eye(3) * 1e-8
    lever = engineering("lever_arm", "accel", np.array([0.03, 0.0, 0.04]), cov)
    assert lever["unit"] == "mm" and lever["value"] == [30.0, 0.0, 40.0] and lever["length_mm"] == 50.0
    g = engineering("g_sensitivity", "gyro", np.arange(9.0) * 1e-4, np.eye(9) * 1e-10)
    assert np.shape(g["value"]) == (3, 3)
    assert g["value"][0][1] == pytest.approx(1e-4 * 9.80665 * 180.0 / math.pi)
    assert unit_factor("time_offset", "gyro") == (1e3, "ms")
    assert unit_factor("bias_random_walk", "gyro") == (180.0 / math.pi, "deg/s/sqrt(s)")
    assert engineering("earth_rotation", "gyro", np.array([1.0]), np.eye(1))["deg_per_h"] == pytest.approx(15.0411,
                                                                                                            abs=1e-3)


@pytest.fixture(scope="module")
def baseline():
    return fit_baseline(simulate_session(2, plan=PLAN, effects=Effects()).session)


def test_every_simulator_mapping_reaches_the_simulator(baseline) -> None:
    """Each mapping moves its own part of the simulator's input, and only it; an unsimulated effect is refused."""
    empty = simulator_input(baseline, lambda: True, [])
    for e in EFFECTS:
        sensor = e.sensors[-1]
        if e.simulate is None:
            with pytest.raises(KeyError):
                simulator_input(baseline, lambda: True, [(e.name, sensor, np.ones(3))])
            continue
        p = 12 if e.name == "pose_tilt" else 9 if e.shape else 1 if e.name in ("earth_rotation", "time_offset") else 3
        acc = simulator_input(baseline, lambda: True, [(e.name, sensor, np.full(p, 1e-3))])
        changed = [k for k, v in acc.coefficients.items() if np.any(v != empty.coefficients[k])]
        changed += ["g_sensitivity"] * bool(np.any(acc.g_sensitivity != empty.g_sensitivity))
        changed += [f"time_offset_{s}" for s in acc.time_offset_s if acc.time_offset_s[s]]
        changed += ["tilt_force"] * (acc.tilt_force is not None)
        assert len(changed) == 1, (e.name, changed)
    truth = simulator_input(baseline, lambda: True, [("temperature_scale", "gyro", np.array([1.0, 2.0, 3.0]))])
    np.testing.assert_array_equal(truth.truth().gyro_temp_scale, [1.0, 2.0, 3.0])


def test_compensation_notes_come_from_the_registry(baseline) -> None:
    out = compensation(baseline.session, [("lever_arm", "accel"), ("scale_nonlinearity_even", "gyro"),
                                          ("not_an_effect", "gyro")])
    assert [c.note for c in out] == [REGISTRY["lever_arm"].not_compensated,
                                     REGISTRY["scale_nonlinearity_even"].not_compensated,
                                     "no parameter for it in the set"]
    assert not any(c.compensated for c in out)
