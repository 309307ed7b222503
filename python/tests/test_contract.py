"""The contract the Python module shares with the tools (issue 30): the same refusals as the CLI,
lpoe.Error for arguments of the wrong type, range limits on arrays, no non-finite model written."""
import os

import numpy as np
import pytest

import lpoe


def test_plan_refuses_rank_deficiency_like_lpoe_plan(inputs):
    m, _, _ = inputs
    # 5 poses of 3 rows for 27 parameters: rank at most 15 (lpoe_plan exits 3).
    with pytest.raises(lpoe.Error, match="identifies only"):
        lpoe.plan(m, 5, candidate_count=300, workspace_count=50, random_draws=2)
    # Identical candidates: one pose's information, whatever the count.
    same = np.tile(np.array([[0.1, -0.4, 0.8, 0.2, 0.5, -0.3]]), (50, 1))
    with pytest.raises(lpoe.Error, match="identifies only"):
        lpoe.plan(m, 12, candidates=same, workspace_count=50, random_draws=2)


def test_plan_refuses_zero_redundancy(inputs):
    m, _, _ = inputs
    # 9 poses x 3 rows = 27 rows for 27 parameters: an exact fit that cannot check itself.
    with pytest.raises(lpoe.Error, match="cannot check itself"):
        lpoe.plan(m, 9, candidate_count=300, workspace_count=50, random_draws=2)
    p = lpoe.plan(m, 10, candidate_count=300, workspace_count=50, random_draws=2)
    assert len(p) == 10 and np.isfinite(p.quality["predicted_rms"])


def test_plan_refuses_an_empty_workspace(inputs):
    m, _, _ = inputs
    with pytest.raises(lpoe.Error, match="workspace"):
        lpoe.plan(m, 12, candidate_count=300, workspace=np.empty((0, 6)), random_draws=2)


@pytest.mark.parametrize("call", [
    lambda m, d: lpoe.calibrate(m, d, verify=5),
    lambda m, d: m.predict(d.q, tool=None),
    lambda m, d: m.predict(d.q, tool=1.0),
])
def test_argument_type_errors_raise_lpoe_error(inputs, call):
    m, d, _ = inputs
    # pybind11's "Unable to cast Python instance" RuntimeError never escapes: lpoe.Error naming
    # the type given.
    with pytest.raises(lpoe.Error, match="wrong type") as e:
        call(m, d)
    assert "NoneType" in str(e.value) or "float" in str(e.value) or "int" in str(e.value)


def test_measurements_have_range_limits(inputs):
    m, d, _ = inputs
    q = np.array(d.q[:10], dtype=float)
    pos = np.array(d.positions[:10], dtype=float)
    q[3, 1] = 1e300
    with pytest.raises(lpoe.Error, match="magnitude above 1e4"):
        lpoe.measurements(m, q, pos)
    q[3, 1] = 0.2
    pos[4, 2] = 1e300
    with pytest.raises(lpoe.Error, match="1e6 mm"):
        lpoe.measurements(m, q, pos)


def test_non_finite_model_is_written_nowhere(inputs, tmp_path):
    m, d, _ = inputs
    p = lpoe.Problem(m, d)
    p.update(np.full(len(p.names), 1e300))
    path = tmp_path / "bad.yaml"
    with pytest.raises(lpoe.Error, match="non-finite"):
        lpoe.write_model(str(path), p.model)
    assert not path.exists()
    lpoe.write_model(str(tmp_path / "good.yaml"), m)
    assert lpoe.read_model(str(tmp_path / "good.yaml")).num_joints == 6


def test_compensate_refuses_a_nominal_model_of_another_robot(inputs, tmp_path):
    m, d, _ = inputs
    text = m.to_yaml()
    # Joint 2 prismatic (twist along z): another robot.
    lines = text.splitlines()
    k = [i for i, l in enumerate(lines) if "name: joint2" in l][0]
    assert "type: revolute" in lines[k + 1]
    lines[k + 1] = lines[k + 1].replace("revolute", "prismatic")
    t = k + 1
    while "twist:" not in lines[t]:
        t += 1
    lines[t] = lines[t].split("twist:")[0] + "twist: [0, 0, 0, 0, 0, 1]"
    other = lpoe.model_from_yaml("\n".join(lines) + "\n")
    with pytest.raises(lpoe.Error, match="joint 2 is prismatic"):
        lpoe.compensate(m, joints=np.array(d.q[:3]), nominal=other)


def test_calibration_report_of_a_non_utf8_model_name(inputs, tmp_path):
    m, d, _ = inputs
    text = m.to_yaml().encode()
    text = text.replace(b"name: joint2", b'name: "j\xff\xfe2"', 1)
    path = tmp_path / "bytes.yaml"
    path.write_bytes(text)
    bad = lpoe.read_model(str(path))
    c = lpoe.calibrate(bad, d)  # nlohmann's type_error 316 escaped as RuntimeError before
    assert c.report["tool"]["name"]
    assert "j\ufffd\ufffd2" in c.report_json


def test_calibration_without_redundancy_is_refused(inputs):
    m, d, _ = inputs
    # 9 points, 27 rows for 27 parameters: not identifiable, as lpoe_calibrate exits 3 (lpoe.calibrate
    # reports a termination other than converged, as for any data that cannot identify the model).
    nine = lpoe.measurements(m, np.array(d.q[:9]), np.array(d.positions[:9]))
    c = lpoe.calibrate(m, nine)
    assert c.termination != "converged"
    assert "cannot check itself" in c.message
    ten = lpoe.measurements(m, np.array(d.q[:10]), np.array(d.positions[:10]))
    assert "cannot check itself" not in lpoe.calibrate(m, ten).message


def test_compensate_and_plan_arrays_have_the_readers_range_limits(inputs):
    m, d, _ = inputs
    seeds = np.array(d.q[:3], dtype=float)
    targets = np.array(d.positions[:3], dtype=float)
    bad_seeds = seeds.copy()
    bad_seeds[1, 2] = 1e300
    with pytest.raises(lpoe.Error, match="magnitude above 1e4"):
        lpoe.compensate(m, targets=targets, seeds=bad_seeds)
    bad_targets = targets.copy()
    bad_targets[2, 0] = 1e300
    with pytest.raises(lpoe.Error, match="magnitude above 1e6 mm"):
        lpoe.compensate(m, targets=bad_targets, seeds=seeds)
    cand = np.tile(seeds, (10, 1))
    cand[4, 0] = 1e5
    with pytest.raises(lpoe.Error, match="candidates: value of magnitude above 1e4"):
        lpoe.plan(m, 12, candidates=cand, workspace_count=50, random_draws=2)
