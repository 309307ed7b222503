"""pytest suite of the lpoe Python module: models, measurements, prediction, errors."""
import os

import numpy as np
import pytest

import lpoe

DATA = os.environ.get("LPOE_DATA_DIR", os.path.join(os.path.dirname(__file__), "..", "..", "data"))
MODEL = os.path.join(DATA, "cobot6.yaml")
IDENT = os.path.join(DATA, "section4", "identification.csv")


@pytest.fixture(scope="module")
def model():
    return lpoe.read_model(MODEL)


def test_read_model(model):
    assert model.num_joints == 6
    assert model.joint_names == ["joint1", "joint2", "joint3", "joint4", "joint5", "joint6"]
    assert model.limits.shape == (6, 2)


def test_predict_matches_pose_and_rows(model):
    rng = np.random.default_rng(1)
    q = rng.uniform(-np.pi, np.pi, size=(50, 6))
    p = model.predict(q)
    assert p.shape == (50, 3)
    for k in (0, 17, 49):
        np.testing.assert_allclose(p[k], model.pose(q[k])[:3, 3], atol=1e-9)
    # One row given as a 1-D array is one configuration.
    np.testing.assert_allclose(model.predict(q[3]), p[3:4], atol=0)


def test_predict_zero_configuration(model):
    # At q = 0 the tool position is the product of the local frames and the tool offset.
    T = np.eye(4)
    for i in range(model.num_joints):
        T = T @ model.joint_origin(i)
    T = T @ model.tool_origin(0)
    np.testing.assert_allclose(model.predict(np.zeros(6))[0], T[:3, 3], atol=1e-9)


def test_predict_rejects_wrong_shape(model):
    with pytest.raises(lpoe.Error, match=r"shape \(M, 6\)"):
        model.predict(np.zeros((4, 5)))
    with pytest.raises(lpoe.Error, match="tool index 3"):
        model.predict(np.zeros((1, 6)), tool=3)


def test_read_measurements(model):
    d = lpoe.read_measurements(IDENT, model)
    assert len(d) == 70
    assert d.q.shape == (70, 6) and d.positions.shape == (70, 3)
    assert d.lines[0] >= 2  # the header is line 1


def test_read_measurements_in_metres(tmp_path, model):
    d = lpoe.read_measurements(IDENT, model)
    lines = open(IDENT).read().splitlines()
    header = [ln for ln in lines if not ln.startswith("#")][0].split(",")
    cols = [header.index(c) for c in ("x", "y", "z")]
    out = []
    for ln in lines:
        f = ln.split(",")
        if not ln.startswith("#") and ln.split(",") != header:
            for c in cols:
                f[c] = repr(float(f[c]) / 1000.0)
        out.append(",".join(f))
    metres = tmp_path / "m.csv"
    metres.write_text("\n".join(out) + "\n")
    dm = lpoe.read_measurements(str(metres), model, length_unit="m")
    np.testing.assert_allclose(dm.positions, d.positions, rtol=1e-12)
    assert "70 rows" in repr(dm)
    with pytest.raises(lpoe.Error, match="length_unit"):
        lpoe.read_measurements(str(metres), model, length_unit="inch")


def test_measurements_from_arrays_round_trip(model):
    rng = np.random.default_rng(2)
    q = rng.uniform(-1, 1, size=(10, 6))
    p = model.predict(q)
    d = lpoe.measurements(model, q, p)
    np.testing.assert_array_equal(d.q, q)
    np.testing.assert_array_equal(d.positions, p)
    with pytest.raises(lpoe.Error, match=r"positions: expected shape \(10, 3\)"):
        lpoe.measurements(model, q, p[:, :2])


def test_bad_file_raises_with_file_and_line(tmp_path, model):
    bad = tmp_path / "bad.csv"
    bad.write_text("q1,q2,q3,q4,q5,q6,x,y,z\n0,0,0,0,0,0,1,2,3\n0,0,0,zero,0,0,1,2,3\n")
    with pytest.raises(lpoe.Error) as e:
        lpoe.read_measurements(str(bad), model)
    assert f"{bad}:3:" in str(e.value)
    with pytest.raises(lpoe.Error, match="bad.yaml"):
        (tmp_path / "bad.yaml").write_text("name: x\njoints: 3\n")
        lpoe.read_model(str(tmp_path / "bad.yaml"))
    with pytest.raises(lpoe.Error):
        lpoe.read_model(str(tmp_path / "missing.yaml"))


def test_write_model_round_trip(tmp_path, model):
    out = tmp_path / "m.yaml"
    lpoe.write_model(str(out), model)
    again = lpoe.read_model(str(out))
    q = np.random.default_rng(3).uniform(-3, 3, size=(100, 6))
    np.testing.assert_allclose(again.predict(q), model.predict(q), atol=1e-9)


def test_joint_jacobian_matches_finite_differences(model):
    q = np.random.default_rng(4).uniform(-2, 2, size=6)
    J = lpoe.joint_jacobian(model, q)
    assert J.shape == (3, 6)
    h = 1e-6
    for i in range(6):
        dq = np.zeros(6)
        dq[i] = h
        fd = (model.predict(q + dq)[0] - model.predict(q - dq)[0]) / (2 * h)
        np.testing.assert_allclose(J[:, i], fd, atol=1e-5)


def test_parameter_jacobian_shape_names_and_rank(model):
    rng = np.random.default_rng(5)
    rows, names = [], None
    for _ in range(40):
        J, names = lpoe.parameter_jacobian(model, rng.uniform(-np.pi, np.pi, size=6))
        rows.append(J)
    assert len(names) == 27 and rows[0].shape == (3, 27)  # cobot6, position data
    assert np.linalg.matrix_rank(np.vstack(rows)) == 27
    with pytest.raises(lpoe.Error, match="parameterization"):
        lpoe.parameter_jacobian(model, np.zeros(6), parameterization="some")


def test_measurement_base_round_trip(tmp_path, model):
    m = model.copy()
    c, s = np.cos(0.3), np.sin(0.3)
    T = np.array([[c, -s, 0, 1500.0], [s, c, 0, -200.0], [0, 0, 1, 30.0], [0, 0, 0, 1]])
    m.measurement_base = T
    np.testing.assert_allclose(m.measurement_base, T, atol=1e-12)
    np.testing.assert_allclose(model.measurement_base, np.eye(4))  # the copy is independent
    lpoe.write_model(str(tmp_path / "r.yaml"), m)
    np.testing.assert_allclose(lpoe.read_model(str(tmp_path / "r.yaml")).measurement_base, T,
                               atol=1e-9)


URDF = os.path.join(os.path.dirname(__file__), "..", "..", "tests", "data", "urdf", "ur_like.urdf")


@pytest.mark.skipif(not os.path.exists(URDF), reason="the source tree's test URDF is not here")
def test_read_model_selects_the_urdf_chain_as_the_tools_do():
    # The same chain selection as every tool's --base_link / --tip_link / --tool_links.
    m = lpoe.read_model(URDF, tip_link="flange", tool_links=["flange", "tool_smr"])
    assert m.num_tools == 2
    q = np.array([0.1, -0.5, 0.7, 0.2, 1.1, -0.4])
    assert np.linalg.norm(m.predict(q, tool=0) - m.predict(q, tool=1)) > 1.0
    with pytest.raises(lpoe.Error, match="not a URDF"):
        lpoe.read_model(MODEL, tool_links=["smr1"])
    with pytest.raises(lpoe.Error):
        lpoe.read_model(URDF, tool_links=["no_such_link"])
