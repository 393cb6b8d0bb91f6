"""The independent line generator (benchmarks/gen_line_indep.py) against its own truth: corrected with the true
parameters its recordings meet their references at the noise floor, one power-on shares one time base, and the
same seed gives the same bytes."""

from __future__ import annotations

import numpy as np
from benchmark_modules import load_benchmark

from station.session.model import Kind


def _gen():  # type: ignore[no-untyped-def]
    return load_benchmark("gen_line_indep")


def test_true_parameters_meet_the_references_and_one_power_on_has_one_time_base() -> None:
    gen = _gen()
    u = gen.generate_unit(7, rack_s=120.0, transfer_s=40.0, hour_s=60.0)
    assert u.rack.t_s[0] == 0.0 and abs(u.rack.t_s[-1] - 119.99) < 1e-9
    assert abs(u.rig.t_s[0] - 160.0) < 1e-9 and u.rig.metadata["boot_count"] == u.rack.metadata["boot_count"]
    assert np.all(np.isnan(u.rack.ref_accel_mps2))
    s = u.val_full
    for tri, y, ref, kind in ((u.unit.accel, s.accel_mps2, s.ref_accel_mps2, Kind.POSE),
                              (u.unit.gyro, s.gyro_radps, s.ref_gyro_radps, Kind.RATE)):
        x = np.linalg.solve(tri.m, (y - tri.b_stat - tri.b_drift * np.exp(-s.t_s[:, None] / tri.tc)).T).T
        segs = s.segments_of(kind)
        assert len(segs) == (6 if kind == Kind.POSE else 18)
        err = np.array([x[g.slice].mean(axis=0) - ref[g.start] for g in segs])
        floor = tri.sigma.max() / np.sqrt(min(g.stop - g.start for g in segs))
        # the stochastic drift (1 % of b_drift) and quantization on top of the white noise: within 10 x its floor
        assert np.sqrt(np.mean(err**2)) < 10.0 * floor + 2.0 * tri.lsb, (kind, err)
        # and the references are what the kinematics does: gravity's norm, the commanded rates
        if kind == Kind.POSE:
            assert np.allclose(np.linalg.norm(ref[[g.start for g in segs]], axis=1), u.unit.gravity)
        else:
            assert np.allclose(np.sort(np.abs(ref[[g.start for g in segs]]).max(axis=1)), np.radians(
                np.sort(np.repeat([50.0, 100.0, 200.0], 6))))


def test_the_same_seed_gives_the_same_recordings() -> None:
    gen = _gen()
    a, b = (gen.generate_unit(3, rack_s=30.0, hour_s=60.0) for _ in range(2))
    assert np.array_equal(a.rig.gyro_radps, b.rig.gyro_radps) and np.array_equal(a.rack.accel_mps2, b.rack.accel_mps2)
    assert not np.array_equal(a.rig.gyro_radps, gen.generate_unit(4, rack_s=30.0, hour_s=60.0).rig.gyro_radps)
