"""The contract the Python module shares with the tools: the same refusals as the CLI,
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


# ---- The contract: no crash, no NaN written, no output lost.

LAYER = """residual_layer:
  kernel: se_ard
  frame: base
  length_scales: [1, 1, 1, 1, 1, 1]
  tool_correlation: 1
  signal_std: {sf}
  noise_std: 0.01
  fitted_rows: 10
  inducing_tools: [0]
  inducing:
    - [0.2, 0.2, 0.2, 0.2, 0.2, 0.2]
  weights:
    - [10, 10, 10]
  variance:
    - [100]
"""


def with_layer(m, sf="0.02"):
    return lpoe.model_from_yaml(m.to_yaml() + LAYER.format(sf=sf))


@pytest.mark.parametrize("tool", [[1.9, 1.9, 1.9], np.array(1.9), np.float64(1.0),
                                  np.array([0.0, 0.0, 0.0]), True])
def test_tool_indices_must_be_integers(inputs, tool):
    m, d, _ = inputs
    with pytest.raises(lpoe.Error, match="integer"):
        m.predict(np.array(d.q[:3]), tool=tool)


def test_integer_tool_indices_are_accepted(inputs):
    m, d, _ = inputs
    q = np.array(d.q[:3])
    ref = m.predict(q, tool=0)
    for tool in [np.array(0), np.int64(0), [0, 0, 0], np.zeros(3, dtype=np.int32), "smr1"]:
        assert np.array_equal(m.predict(q, tool=tool), ref)


def test_measurement_base_must_be_a_finite_rigid_transform(inputs):
    m, d, _ = inputs
    c = m.copy()
    bad = np.eye(4)
    bad[0, 3] = np.nan
    with pytest.raises(lpoe.Error, match="NaN"):
        c.measurement_base = bad
    scaled = np.eye(4)
    scaled[:3, :3] *= 2
    with pytest.raises(lpoe.Error, match="rigid"):
        c.measurement_base = scaled
    assert np.array_equal(c.measurement_base, np.eye(4))  # unchanged by the refusals
    ok = np.eye(4)
    ok[:3, 3] = [100, -50, 20]
    c.measurement_base = ok
    assert np.allclose(c.measurement_base, ok)
    # lpoe.compensate then returns finite joints.
    r = lpoe.compensate(c, joints=np.array(d.q[:3]), nominal=m)
    assert np.all(np.isfinite(r.q))


def test_residual_layer_with_an_offset_tcp_is_an_error_not_an_abort(inputs):
    m, d, _ = inputs
    layered = with_layer(m)
    with pytest.raises(lpoe.Error, match="residual layer corrects only the tools"):
        lpoe.compensate(layered, targets=np.array(d.positions[:3]), seeds=np.array(d.q[:3]),
                        tcp=[0, 0, 100])
    # A measured tool is fine.
    r = lpoe.compensate(layered, targets=np.array(d.positions[:3]), seeds=np.array(d.q[:3]))
    assert np.all(np.isfinite(r.q))


@pytest.mark.parametrize("sf", ["1e200", "nan", "0"])
def test_model_numbers_out_of_range_name_the_line(inputs, sf):
    m, _, _ = inputs
    text = m.to_yaml() + LAYER.format(sf=sf)
    expected_line = text.splitlines().index("  signal_std: " + sf) + 1
    with pytest.raises(lpoe.Error, match=":%d: 'signal_std'" % expected_line):
        lpoe.model_from_yaml(text)


def test_program_language_must_fit_the_text(inputs):
    m, d, _ = inputs
    program = "def p():\n  movej([0.1, -1.2, 1.0, 0.3, 0.5, 0.2])\nend\n"
    with pytest.raises(lpoe.Error, match="reads as a urscript program"):
        lpoe.compensate_program(m, m, program, language="rapid")


def test_targets_only_on_a_long_name(inputs):
    m, _, _ = inputs
    name = "Waypoint_" + "a" * 100000
    program = ("def p():\n  global " + name + "=[0.1, -1.2, 1.0, 0.3, 0.5, 0.2]\n  movej(" + name +
               ")\nend\n")
    r = lpoe.compensate_program(m, m, program, language="urscript", targets_only="Waypoint_.*")
    assert [t["status"] for t in r.targets] == ["compensated"]
    r = lpoe.compensate_program(m, m, program, language="urscript", targets_only="(a|a)*b")
    assert [t["status"] for t in r.targets] == ["not_selected"]
